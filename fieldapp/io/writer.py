"""Writing a session as it is captured: every capture lands durably or not at all.

A capture's images are written first (each atomically), then ``session.json`` is rewritten
atomically with the capture added and the SHA-256 of each of its files. A crash at any point
leaves a folder whose ``session.json`` lists only complete captures; stray image files of an
unlisted capture are overwritten when that capture is taken again.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fieldapp.errors import FieldappError
from fieldapp.io.calibration import Calibration, save_calibration
from fieldapp.io.durable import write_bytes_durably, write_json_durably
from fieldapp.io.images import depth_m_to_units, encode_png, sha256_hex
from fieldapp.io.session import (
    SESSION_FILE,
    SESSION_FORMAT,
    BasePose,
    Capture,
    Session,
    SessionDocument,
    load_session,
    now_iso,
)

CALIBRATION_FILE = "calibration.json"


def capture_paths(station: int, view: int, target: str | None = None) -> dict[str, str]:
    """Where a capture's files go, relative to the session folder."""
    folder = f"frames/s{station:02d}/v{view}" + (f"-{target}" if target else "")
    return {
        "depth": f"{folder}/depth.png",
        "color": f"{folder}/color.png",
        "ir": f"{folder}/ir.png",
    }


class SessionWriter:
    """Creates or reopens a session folder and adds captures to it, durably and thread-safely."""

    def __init__(self, session: Session) -> None:
        self.session = session
        self._lock = threading.Lock()

    @classmethod
    def create(
        cls,
        folder: Path,
        session_id: str,
        calibration: Calibration,
        extra: dict[str, Any] | None = None,
    ) -> SessionWriter:
        """Start a new session in ``folder`` (which must not hold a session yet)."""
        if (folder / SESSION_FILE).exists():
            raise FieldappError(f"{folder / SESSION_FILE}: a session already exists here")
        folder.mkdir(parents=True, exist_ok=True)
        save_calibration(folder / CALIBRATION_FILE, calibration)
        document = SessionDocument(
            format=SESSION_FORMAT,
            id=session_id,
            created=now_iso(),
            calibration=CALIBRATION_FILE,
            captures=[],
            **(extra or {}),
        )
        writer = cls(Session(folder, document, calibration))
        writer._save_document()
        return writer

    @classmethod
    def open(cls, folder: Path) -> SessionWriter:
        """Reopen an existing session to add what it is missing."""
        return cls(load_session(folder, allow_empty=True))

    def has(self, station: int, view: int, target: str | None = None) -> bool:
        return any(c.key == (station, view, target) for c in self.session.captures)

    def add_capture(
        self,
        station: int,
        view: int,
        depth_m: NDArray[np.floating],
        color: NDArray[np.uint8] | None,
        ir: NDArray[np.uint16] | None = None,
        angle_deg: float | None = None,
        base_pose: BasePose | None = None,
        target: str | None = None,
        **extra: Any,
    ) -> Capture:
        """Write one capture's images, then list it in ``session.json``; returns its entry.

        ``depth_m``: (H, W) metres, NaN or 0 where missing. ``color``: (H, W, 3) uint8 RGB, or
        ``None`` for a depth-only capture.
        """
        camera = self.session.calibration.depth_camera
        expected = (camera.height, camera.width)
        color_hw = expected if color is None else color.shape[:2]
        if depth_m.shape != expected or color_hw != expected:
            raise ValueError(
                f"capture images are {depth_m.shape} / {color_hw}, the calibration says {expected}"
            )
        with self._lock:
            if self.has(station, view, target):
                raise FieldappError(f"station {station} view {view} is already captured")
            paths = capture_paths(station, view, target)
            encoded = {"depth": encode_png(depth_m_to_units(depth_m, camera.depth_scale))}
            if color is not None:
                encoded["color"] = encode_png(color, rgb=True)
            if ir is not None:
                encoded["ir"] = encode_png(ir)
            for name, data in encoded.items():
                write_bytes_durably(self.session.folder / paths[name], data)
            fields: dict[str, Any] = {"target": target} if target else {}
            capture = Capture(
                station=station,
                view=view,
                depth=paths["depth"],
                color=paths["color"] if color is not None else None,
                ir=paths["ir"] if ir is not None else None,
                angle_deg=angle_deg,
                captured_at=now_iso(),
                base_pose=base_pose,
                sha256={name: sha256_hex(data) for name, data in encoded.items()},
                **fields,
                **extra,
            )
            updated = self.session.document.model_copy(
                update={"captures": [*self.session.captures, capture]}
            )
            self._save_document(updated)  # the capture is listed only once this has landed
            self.session.document = updated
            return capture

    def _save_document(self, document: SessionDocument | None = None) -> None:
        document = document or self.session.document
        write_json_durably(
            self.session.folder / SESSION_FILE, document.model_dump(mode="json", exclude_none=True)
        )
