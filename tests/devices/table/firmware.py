"""The real Grbl 1.1 firmware, compiled as a Linux program (grbl-sim), behind a pseudo-terminal.

grbl-sim (github.com/grbl/grbl-sim, built against gnea/grbl 1.1h) runs the firmware's own
code and reads the serial bytes on stdin and writes them on stdout. :class:`FirmwarePty`
starts it in a folder of its own (its ``EEPROM.DAT`` lives there) and relays its stdio to the
master side of a pty, so the driver opens the slave path exactly as it opens
``/dev/ttyUSB0``. Faults come from outside the firmware: :meth:`FirmwarePty.freeze` stops the
process (a controller that no longer answers), :meth:`FirmwarePty.unplug` kills it and closes
the pty (the USB cable pulled).

Nothing of grbl-sim is in this repository: ``GRBL_SIM_EXE`` names an executable built by hand
(docs/TABLE.md says how), and the tests that use it skip without it.
"""

from __future__ import annotations

import os
import select
import shutil
import signal
import subprocess
import threading
import tty
from pathlib import Path

GRBL_SIM_ENV = "GRBL_SIM_EXE"


def grbl_sim_executable() -> Path | None:
    """The grbl-sim executable named by ``GRBL_SIM_EXE``, or None."""
    value = os.environ.get(GRBL_SIM_ENV, "")
    return Path(value) if value and os.access(value, os.X_OK) else None


class FirmwarePty:
    """grbl-sim in real time (``-t 1``), its serial port on a pty at :attr:`device_path`.

    ``folder`` holds its EEPROM; a blank one makes the first boot print ``error:7`` and the
    default settings before the banner, as a freshly flashed board does."""

    def __init__(self, executable: Path, folder: Path) -> None:
        self._master, slave = os.openpty()
        tty.setraw(slave)
        self.device_path = os.ttyname(slave)
        self._slave = slave  # kept open so the pty stays up between the driver's opens
        # grbl-sim writes with stdio and never flushes: on a pipe its answers would wait in a
        # 4 KiB buffer (its own unbuffering line is commented out in main.c)
        unbuffered = ["stdbuf", "-o0"] if shutil.which("stdbuf") else []
        self._process = subprocess.Popen(
            [*unbuffered, str(executable), "-n", "-t", "1", "-s", os.devnull, "-b", os.devnull],
            cwd=folder,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            bufsize=0,
        )
        self._closed = threading.Event()
        self._threads = [
            threading.Thread(target=self._to_firmware, daemon=True),
            threading.Thread(target=self._from_firmware, daemon=True),
        ]
        for thread in self._threads:
            thread.start()

    def freeze(self) -> None:
        """SIGSTOP: the firmware neither moves nor answers until :meth:`thaw`."""
        self._process.send_signal(signal.SIGSTOP)

    def thaw(self) -> None:
        self._process.send_signal(signal.SIGCONT)

    def unplug(self) -> None:
        """Kill the firmware and close the pty's master: the driver's port reads nothing more."""
        self.close()

    def close(self) -> None:
        if self._closed.is_set():
            return
        self._closed.set()
        self._process.send_signal(signal.SIGCONT)
        self._process.kill()
        self._process.wait(timeout=5)
        for thread in self._threads:
            thread.join(timeout=2)
        for fd in (self._master, self._slave):
            os.close(fd)
        for pipe in (self._process.stdin, self._process.stdout):
            if pipe is not None:
                pipe.close()

    def _to_firmware(self) -> None:
        assert self._process.stdin is not None
        while not self._closed.is_set():
            if not select.select([self._master], [], [], 0.05)[0]:
                continue
            try:
                data = os.read(self._master, 4096)
                self._process.stdin.write(data)
            except OSError:
                return

    def _from_firmware(self) -> None:
        assert self._process.stdout is not None
        stdout = self._process.stdout.fileno()
        while not self._closed.is_set():
            if not select.select([stdout], [], [], 0.05)[0]:
                continue
            try:
                data = os.read(stdout, 4096)
                if not data:
                    return
                os.write(self._master, data)
            except OSError:
                return
