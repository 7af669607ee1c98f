"""``fieldapp import folder``: a folder of depth images (colour and IR where present) into a
session."""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from fieldapp.errors import FieldappError
from fieldapp.imports.camera import (
    camera_from_options,
    import_calibration,
    read_rig_file,
    turntable_fields,
)
from fieldapp.imports.captures import PlannedCapture, group_files, plan_captures
from fieldapp.imports.images import Unusable, read_color_rgb, read_depth_m, read_ir_u16
from fieldapp.imports.names import image_files, parse_name
from fieldapp.io.calibration import Calibration
from fieldapp.io.session import now_iso
from fieldapp.io.writer import SessionWriter

log = logging.getLogger(__name__)

ImageT = TypeVar("ImageT", np.uint8, np.uint16)


@dataclass
class FolderOptions:
    """How to read the folder: the camera (``intrinsics`` text or a ``calibration`` file), the
    depth units, the table's step and where its axis stands."""

    intrinsics: str | None = None
    calibration: Path | None = None
    depth_scale: float = 1000.0
    step_deg: float | None = None
    axis_distance_m: float = 0.0
    session_id: str | None = None


@dataclass
class ImportResult:
    """What an import wrote, and one line for everything it could not use."""

    out: Path
    captures: int
    depth_only: int
    lines: list[str] = field(default_factory=list)


def import_folder(folder: Path, out: Path, options: FolderOptions) -> ImportResult:
    """Write a session in ``out`` from the depth images in ``folder``."""
    if not folder.is_dir():
        raise FieldappError(f"{folder}: no such folder")
    lines: list[str] = []
    named = [parse_name(p, folder) for p in image_files(folder)]
    if not named:
        raise FieldappError(f"{folder}: no image files (.png, .tif, .jpg, .bmp, .npy) in it")
    planned, step = plan_captures(group_files(named, lines), options.step_deg, lines)
    if not planned:
        raise FieldappError(f"{folder}: no depth image found\n" + "\n".join(lines))
    first_depth = _first_readable_depth(planned, options.depth_scale)
    height, width = first_depth.shape
    camera = camera_from_options(
        options.intrinsics, options.calibration, width, height, options.depth_scale
    )
    rig = read_rig_file(options.calibration) if options.calibration else None
    calibration = import_calibration(camera, step, options.axis_distance_m, rig)
    if calibration.stations is not None:
        _check_stations(planned, set(calibration.stations.to_reference))
        calibration = only_stations(calibration, {c.station for c in planned}, lines)
    provenance: dict[str, Any] = {
        "imported": {"from": str(folder.resolve()), "at": now_iso(), "by": "folder"}
    }
    provenance |= turntable_fields(options.axis_distance_m)
    writer = SessionWriter.create(
        out, options.session_id or folder.resolve().name, calibration, extra=provenance
    )
    result = ImportResult(out, 0, 0, lines)
    for capture in planned:
        _write_capture(writer, capture, options.depth_scale, (height, width), result)
    if result.captures == 0:
        raise FieldappError(f"{folder}: no capture could be imported\n" + "\n".join(lines))
    return result


def _first_readable_depth(planned: list[PlannedCapture], depth_scale: float) -> NDArray[np.float32]:
    for capture in planned:
        try:
            return read_depth_m(capture.files["depth"], depth_scale)
        except Unusable:
            continue
    raise FieldappError(
        "no readable depth image: " + ", ".join(str(c.files["depth"]) for c in planned[:5])
    )


def only_stations(calibration: Calibration, stations: set[int], lines: list[str]) -> Calibration:
    """The calibration with only the imported stations (and the reference), so that the
    stations not imported are not reported missing."""
    assert calibration.stations is not None
    kept = stations | {calibration.stations.reference}
    dropped = sorted(set(calibration.stations.to_reference) - kept)
    if not dropped:
        return calibration
    lines.append(f"calibration stations {', '.join(map(str, dropped))} not used: no images of them")
    to_reference = {s: T for s, T in calibration.stations.to_reference.items() if s in kept}
    kept_stations = calibration.stations.model_copy(update={"to_reference": to_reference})
    return calibration.model_copy(update={"stations": kept_stations})


def _check_stations(planned: list[PlannedCapture], calibrated: set[int]) -> None:
    missing = sorted({c.station for c in planned} - calibrated)
    if missing:
        raise FieldappError(
            f"stations {', '.join(map(str, missing))} are in the file names but not in the "
            f"calibration's stations ({', '.join(map(str, sorted(calibrated)))}): give "
            "--calibration with every station, or import one station at a time"
        )


def _write_capture(
    writer: SessionWriter,
    capture: PlannedCapture,
    depth_scale: float,
    size: tuple[int, int],
    result: ImportResult,
) -> None:
    where = f"station {capture.station} view {capture.view}"
    try:
        depth_m = read_depth_m(capture.files["depth"], depth_scale)
    except Unusable as error:
        result.lines.append(f"{error} ({where} not imported)")
        return
    if depth_m.shape != size:
        result.lines.append(
            f"{capture.files['depth']}: not used: {depth_m.shape[1]} x {depth_m.shape[0]}, the "
            f"first depth image is {size[1]} x {size[0]} ({where} not imported)"
        )
        return
    color = _optional(capture, "color", read_color_rgb, size, result.lines)
    ir = _optional(capture, "ir", read_ir_u16, size, result.lines)
    writer.add_capture(
        capture.station, capture.view, depth_m, color, ir=ir, angle_deg=capture.angle_deg
    )
    result.captures += 1
    result.depth_only += color is None


def _optional(
    capture: PlannedCapture,
    kind: str,
    reader: Callable[[Path], NDArray[ImageT]],
    size: tuple[int, int],
    lines: list[str],
) -> NDArray[ImageT] | None:
    """The capture's ``kind`` image when present, readable and of the depth's size."""
    path = capture.files.get(kind)
    if path is None:
        return None
    try:
        image = reader(path)
    except Unusable as error:
        lines.append(str(error))
        return None
    if image.shape[:2] != size:
        lines.append(
            f"{path}: not used as {kind}: {image.shape[1]} x {image.shape[0]}, the depth image "
            f"is {size[1]} x {size[0]} ({kind} must be registered to depth pixel for pixel)"
        )
        return None
    return image
