"""Where the table was left when its port closed: what lets a driver trust a power-up.

Opening the port resets most Arduino-based boards through DTR, and Grbl starts a power-up with
its machine position at 0 wherever the table stands (``main.c``; a Ctrl-X keeps it). The
work offset (``G54``, EEPROM) survives, so the angles stay right only if the table stood at
machine zero when the port closed. :class:`ParkFile` remembers, per port, whether it did: the
driver writes ``moved`` before it turns the table and ``parked`` once it has turned it back
to machine zero (:meth:`~devices.table.driver.GrblTable.park`) or the operator has confirmed
that it stands there. After a power-up banner, a port last ``moved`` has an unknown position;
a port never seen is trusted (a new rig, set up at its zero).
"""

from __future__ import annotations

import json
import logging
import os
import tempfile
import threading
from pathlib import Path
from typing import Literal

log = logging.getLogger(__name__)

ParkState = Literal["parked", "moved"]
STATES: tuple[ParkState, ...] = ("parked", "moved")


class ParkFile:
    """Per port, ``parked`` or ``moved``, in a small JSON file (``{"/dev/ttyUSB0": "parked"}``)
    written atomically. An unreadable file is taken as no record, with a warning."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._lock = threading.Lock()

    def state(self, port: str) -> ParkState | None:
        """What was last recorded for ``port``; None when nothing was."""
        value = self._read().get(port)
        return value if value in STATES else None

    def record(self, port: str, state: ParkState) -> None:
        with self._lock:
            states = self._read()
            if states.get(port) == state:
                return
            states[port] = state
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                handle, temporary = tempfile.mkstemp(dir=self.path.parent, suffix=".tmp")
                with os.fdopen(handle, "w") as file:
                    json.dump(states, file, indent=1, sort_keys=True)
                    file.flush()
                    os.fsync(file.fileno())
                os.replace(temporary, self.path)
            except OSError as error:
                log.warning("%s: cannot record the table %s (%s)", self.path, state, error)

    def _read(self) -> dict[str, str]:
        try:
            data = json.loads(self.path.read_text())
        except FileNotFoundError:
            return {}
        except (OSError, ValueError) as error:
            log.warning("%s: unreadable (%s): taken as no record", self.path, error)
            return {}
        if not isinstance(data, dict):
            log.warning("%s: not an object: taken as no record", self.path)
            return {}
        return {str(k): str(v) for k, v in data.items()}
