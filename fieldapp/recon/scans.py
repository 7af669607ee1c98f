"""Reading a session's captures into station clouds (back-projection and Eq. 9, per station)."""

from __future__ import annotations

import logging
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4
from fieldapp.errors import FieldappError, FormatError
from fieldapp.io.session import Capture, Session
from fieldapp.recon.backproject import backproject, ray_table
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.settings import CropSettings
from fieldapp.recon.station import T_view0_view, station_cloud

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class StationScan:
    """One station's views joined in its view-0 camera frame."""

    station: int
    cloud: Cloud
    views: list[int]


def captures_by_station(session: Session) -> dict[int, list[Capture]]:
    grouped: dict[int, list[Capture]] = defaultdict(list)
    for capture in session.captures:
        if getattr(capture, "target", None) is None:
            grouped[capture.station].append(capture)
    return {s: sorted(c, key=lambda c: c.view) for s, c in sorted(grouped.items())}


def turntable_axis_point(T_view_next: Matrix4, views: int) -> NDArray[np.float64]:
    """(3,) a point on the turntable axis in view-0 frame: the mean camera centre of a turn."""
    centres = [T_view0_view(T_view_next, view)[:3, 3] for view in range(max(views, 1))]
    return np.mean(centres, axis=0)  # type: ignore[no-any-return]


def read_station(
    session: Session,
    station: int,
    captures: list[Capture],
    crop: CropSettings,
    rays: NDArray[np.float64],
    warnings: list[str],
) -> StationScan | None:
    """Back-project every readable capture of ``station`` and join them in view 0; a capture
    that cannot be read is skipped with a warning. ``None`` when nothing was readable."""
    view_step = session.calibration.view_step
    if view_step is None:
        raise FieldappError(f"{session.folder}: the calibration has no view_step")
    views: dict[int, Cloud] = {}
    for capture in captures:
        try:
            images = session.read_capture(capture)
        except FormatError as error:
            warnings.append(f"station {station} view {capture.view} skipped: {error}")
            continue
        views[capture.view] = backproject(
            images.depth_m, images.color, rays, crop.radius_m, crop.min_depth_m
        )
    if not views:
        return None
    cloud = station_cloud(views, view_step.matrix)
    return StationScan(station, cloud, sorted(views))


def read_stations(
    session: Session, crop: CropSettings, warnings: list[str]
) -> Iterator[tuple[int, int, StationScan | None]]:
    """Yield (index, count, scan) for every station that has captures, in station order."""
    rays = ray_table(session.calibration.depth_camera.intrinsics())
    grouped = captures_by_station(session)
    for index, (station, captures) in enumerate(grouped.items()):
        yield index, len(grouped), read_station(session, station, captures, crop, rays, warnings)
