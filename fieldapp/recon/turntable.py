"""Plant-on-turntable sessions: the camera stands still, the plant turns on the table.

The session says so with ``"turntable": {"carries": "plant"}``. The calibration's
``view_step.matrix`` then describes the camera orbiting the plant (the plant turning by +step
is the camera turning by -step about the table's axis, in the plant's frame), so Eq. 9 joins
the plant's views as it joins a field station's, but it would smear everything that does not
turn (the room, the bench) around the axis. So, per view, before joining:

1. the table's axis is taken from ``view_step.matrix`` (its rotation axis and a point on it);
2. the working volume is kept: points within ``working_radius_m`` of the axis, from 2 cm below
   the soil surface (the densest height near the axis, where the plant stands) upwards; the
   room is masked;
3. each view's turn is the commanded step (``angle_deg`` of the captures, else view x step);
   when the view step is nominal (no board was seen, ``view_step.nominal``), it is refined by
   ICP about the axis (:func:`~fieldapp.recon.turntable_axis.place_views`): one degree of
   freedom, the angle about the axis, so nothing else can drift.

The field frame: z up along the axis, origin on the axis at the soil surface, x along the
camera's view.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4, make_transform
from fieldapp.errors import FieldappError
from fieldapp.io.session import CaptureImages, Session
from fieldapp.recon.backproject import backproject, ray_table
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.exg import Separation, choose_separation, excess_green, otsu_threshold
from fieldapp.recon.scans import StationScan, captures_by_station, read_images
from fieldapp.recon.settings import CropSettings
from fieldapp.recon.turntable_axis import (
    ICP_ABOVE_SURFACE_M,
    TableAxis,
    place_views,
    table_axis,
)

log = logging.getLogger(__name__)

DEFAULT_WORKING_RADIUS_M = 0.35
"""How far from the axis the plant may reach when the session does not say."""
SURFACE_RADIUS_M = 0.10
"""The soil surface is looked for this close to the axis (inside any pot or tray)."""
SURFACE_BIN_M = 0.005
BELOW_SURFACE_M = 0.02
SOIL_STRIDE = 8


@dataclass
class TurntableScan:
    """The joined scan of a plant-on-turntable session, where its field frame is, and how the
    views were placed (for ``report.json``)."""

    scan: StationScan
    T_field_view0: Matrix4
    report: dict[str, object] = field(default_factory=dict)


@dataclass
class _View:
    view: int
    commanded_deg: float
    points: Cloud
    height_m: NDArray[np.float64]


def read_turntable(
    session: Session, crop: CropSettings, top_m: float, refine: bool
) -> tuple[TurntableScan | None, list[str]]:
    """Read, mask, place and join the views of a plant-on-turntable session; ``None`` when no
    capture could be read. ``crop``: the back-projection's range; ``top_m``: how far above
    the soil surface the working volume reaches; ``refine``: whether a nominal view step may
    be refined by ICP about the axis. Returns the scan and the warnings."""
    view_step = session.calibration.view_step
    if view_step is None:
        raise FieldappError(f"{session.folder}: the calibration has no view_step")
    station, images, warnings = _station_images(session)
    if not images:
        return None, warnings
    axis = table_axis(view_step.matrix, view_step.angle_deg)
    radius_m = _working_radius_m(session)
    views, surface_m = _working_volume(session, images, axis, radius_m, crop, top_m)
    separation, threshold = _separation(views, images)
    plant = [_plant_mask(v, separation, threshold) for v in views]
    turns, report = place_views(
        [v.commanded_deg for v in views],
        [
            v.points.points[m & (v.height_m > surface_m + ICP_ABOVE_SURFACE_M)]
            for v, m in zip(views, plant, strict=True)
        ],
        axis,
        [v.view for v in views],
        view_step.nominal is not None and refine,
        warnings,  # read_turntable's own list: place_views adds a warning when ICP failed
    )
    T_view0 = [axis.T_view0_view(turn) for turn in turns]
    scan = StationScan(
        station,
        Cloud.concatenate(
            [
                v.points.select(m).transformed(T)
                for v, m, T in zip(views, plant, T_view0, strict=True)
            ]
        ),
        Cloud.concatenate(
            [_soil(v, surface_m).transformed(T) for v, T in zip(views, T_view0, strict=True)]
        ),
        [v.view for v in views],
        threshold if np.isfinite(threshold) else 0.0,
        int(sum(int(np.isfinite(i.depth_m).sum()) for i in images)),
        separation,
    )
    report |= {"working_radius_m": radius_m, "kept_in_volume": sum(len(v.points) for v in views)}
    return TurntableScan(scan, _T_field_view0(axis, surface_m), report), warnings


def _working_radius_m(session: Session) -> float:
    table = session.document.turntable
    return (table.working_radius_m if table else None) or DEFAULT_WORKING_RADIUS_M


def _working_volume(
    session: Session,
    images: list[CaptureImages],
    axis: TableAxis,
    radius_m: float,
    crop: CropSettings,
    top_m: float,
) -> tuple[list[_View], float]:
    """Each view's points in the working volume (up to ``top_m`` above the soil surface), and
    the soil surface's height on the axis."""
    rays = ray_table(session.calibration.depth_camera.intrinsics())
    step_deg = session.calibration.view_step.angle_deg if session.calibration.view_step else 0.0
    views = [_in_volume(image, axis, rays, radius_m, crop, step_deg) for image in images]
    try:
        surface_m = _surface_height(views, axis)
    except ValueError:
        raise FieldappError(
            f"{session.folder / session.document.calibration}: view_step.matrix: nothing was "
            f"measured within {SURFACE_RADIUS_M * 100:g} cm of the turntable's axis it gives"
        ) from None
    return [_above(v, surface_m - BELOW_SURFACE_M, surface_m + top_m) for v in views], surface_m


def _separation(views: list[_View], images: list[CaptureImages]) -> tuple[Separation, float]:
    """Colour or geometry (see :func:`choose_separation`), judged in the working volume, and
    the ExG threshold (infinite by geometry)."""
    exg = excess_green(Cloud.concatenate([v.points for v in views]).colors)
    has_colour = all(i.capture.color is not None for i in images)
    separation = choose_separation(exg if has_colour else None)
    if separation.by_geometry or len(exg) == 0:
        return separation, float("inf")
    return separation, otsu_threshold(exg)


def _station_images(session: Session) -> tuple[int, list[CaptureImages], list[str]]:
    """The station turned, its readable captures' images, and the warnings."""
    grouped = captures_by_station(session)
    if not grouped:
        return 0, [], []
    station = session.calibration.stations.reference if session.calibration.stations else 0
    if station not in grouped:
        station = min(grouped)
    ignored = []
    if len(grouped) > 1:
        others = ", ".join(str(s) for s in grouped if s != station)
        ignored.append(f"a turntable session has one station: stations {others} ignored")
    images, skipped = read_images(session, station, grouped[station])
    return station, images, ignored + skipped


def _in_volume(
    image: CaptureImages,
    axis: TableAxis,
    rays: NDArray[np.float64],
    radius_m: float,
    crop: CropSettings,
    step_deg: float,
) -> _View:
    """A view's points within ``radius_m`` of the axis (camera frame)."""
    capture = image.capture
    cloud = backproject(image.depth_m, image.color, rays, crop.radius_m, crop.min_depth_m)
    radius, height = axis.radius_height(cloud.points)
    inside = radius <= radius_m
    commanded = capture.angle_deg if capture.angle_deg is not None else capture.view * step_deg
    return _View(capture.view, commanded, cloud.select(inside), height[inside])


def _surface_height(views: list[_View], axis: TableAxis) -> float:
    """Height along the axis of the soil surface: the densest height near the axis."""
    heights = []
    for v in views:
        radius, height = axis.radius_height(v.points.points)
        heights.append(height[radius <= SURFACE_RADIUS_M])
    near = np.concatenate(heights)
    if len(near) == 0:
        raise ValueError("nothing near the axis")
    bins = np.arange(near.min(), near.max() + 2 * SURFACE_BIN_M, SURFACE_BIN_M)
    counts, edges = np.histogram(near, bins=bins)
    peak = (edges[np.argmax(counts)] + edges[np.argmax(counts) + 1]) / 2.0
    return float(np.median(near[np.abs(near - peak) <= 2 * SURFACE_BIN_M]))


def _above(view: _View, low_m: float, high_m: float) -> _View:
    keep = (view.height_m >= low_m) & (view.height_m <= high_m)
    return _View(view.view, view.commanded_deg, view.points.select(keep), view.height_m[keep])


def _plant_mask(view: _View, separation: Separation, threshold: float) -> NDArray[np.bool_]:
    """Which of a view's points go on as plant candidates: all (geometry splits them after
    levelling) or the green ones."""
    if separation.by_geometry:
        return np.ones(len(view.points), dtype=bool)
    return excess_green(view.points.colors) > threshold


def _soil(view: _View, surface_m: float) -> Cloud:
    near = np.flatnonzero(np.abs(view.height_m - surface_m) <= BELOW_SURFACE_M)
    return view.points.select(near[::SOIL_STRIDE])


def _T_field_view0(axis: TableAxis, surface_m: float) -> Matrix4:
    """Field frame: z up the axis, origin on it at the soil surface, x along the camera's view."""
    ez = axis.up
    ex = np.array([0.0, 0.0, 1.0]) - ez[2] * ez
    ex /= np.linalg.norm(ex)
    R = np.stack([ex, np.cross(ez, ex), ez])
    origin = axis.point_m + surface_m * axis.up
    return make_transform(R, -R @ origin)
