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
   ICP about the axis: each view's plant points against the views already placed, one degree
   of freedom (the angle about the axis), so nothing else can drift.

The field frame: z up along the axis, origin on the axis at the soil surface, x along the
camera's view.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from devices.geometry import Matrix4, make_transform, transform_points
from fieldapp.errors import FieldappError, FormatError
from fieldapp.io.session import CaptureImages, Session
from fieldapp.recon.backproject import backproject, ray_table
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.depth_only import read_scan_capture
from fieldapp.recon.filters import Separation, choose_separation, excess_green, otsu_threshold
from fieldapp.recon.scans import StationScan, captures_by_station
from fieldapp.recon.settings import ReconstructionSettings

log = logging.getLogger(__name__)

DEFAULT_WORKING_RADIUS_M = 0.35
"""How far from the axis the plant may reach when the session does not say."""
SURFACE_RADIUS_M = 0.10
"""The soil surface is looked for this close to the axis (inside any pot or tray)."""
SURFACE_BIN_M = 0.005
BELOW_SURFACE_M = 0.02
ICP_ABOVE_SURFACE_M = 0.02
ICP_DISTANCES_M = (0.01, 0.006, 0.004)
SEARCH_STEP_DEG = 0.25
ICP_ROUNDS = 2
ICP_ITERATIONS = 15
ICP_MIN_PAIRS = 50
MAX_REFINEMENT_DEG = 5.0
SOIL_STRIDE = 8
CAMERA_UP = np.array([0.0, -1.0, 0.0])


def carries_plant(session: Session) -> bool:
    """Whether ``session`` is a plant-on-turntable session."""
    table = session.document.turntable
    return table is not None and table.carries == "plant"


@dataclass(frozen=True)
class TableAxis:
    """The table's axis in the (fixed) camera frame: ``point_m`` (3,) on it, ``up`` (3,) unit,
    and ``rad_per_deg``: the signed turn about ``up`` that joins the views per degree of
    table angle (view_step's rotation over its ``angle_deg``)."""

    point_m: NDArray[np.float64]
    up: NDArray[np.float64]
    rad_per_deg: float

    def T_view0_view(self, turn_deg: float) -> Matrix4:
        """Maps a view taken ``turn_deg`` of table angle after view 0 into view 0."""
        R = _rotation(self.up, self.rad_per_deg * turn_deg)
        return make_transform(R, self.point_m - R @ self.point_m)

    def radius_height(
        self, points_m: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(N,) distance from the axis and (N,) height along it of ``points_m`` (N, 3)."""
        relative = points_m - self.point_m
        height = relative @ self.up
        radial = relative - height[:, None] * self.up
        return np.linalg.norm(radial, axis=1), height


def _rotation(axis: NDArray[np.float64], angle_rad: float) -> NDArray[np.float64]:
    """Rodrigues: the rotation by ``angle_rad`` about the unit ``axis``."""
    x, y, z = axis
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + np.sin(angle_rad) * K + (1.0 - np.cos(angle_rad)) * (K @ K)  # type: ignore[no-any-return]


def table_axis(T_view_next: Matrix4, step_deg: float) -> TableAxis:
    """The axis of ``view_step.matrix`` (a turn of ``step_deg`` of the table), pointing up in
    an upright camera."""
    R, t = T_view_next[:3, :3], T_view_next[:3, 3]
    angle = float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))
    if angle < 1e-6:
        raise FieldappError("view_step.matrix does not turn: no table axis")
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    axis /= np.linalg.norm(axis)
    if axis @ CAMERA_UP < 0:
        axis, angle = -axis, -angle
    point = np.asarray(np.linalg.lstsq(np.eye(3) - R, t, rcond=None)[0], dtype=np.float64)
    return TableAxis(point, axis, angle / step_deg)


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
    session: Session, settings: ReconstructionSettings, warnings: list[str]
) -> TurntableScan | None:
    """Read, mask, place and join the views of a plant-on-turntable session; ``None`` when no
    capture could be read."""
    view_step = session.calibration.view_step
    if view_step is None:
        raise FieldappError(f"{session.folder}: the calibration has no view_step")
    station, images = _station_images(session, warnings)
    if not images:
        return None
    axis = table_axis(view_step.matrix, view_step.angle_deg)
    table = session.document.turntable
    radius_m = (table.working_radius_m if table else None) or DEFAULT_WORKING_RADIUS_M
    rays = ray_table(session.calibration.depth_camera.intrinsics())
    views = [
        _in_volume(image, axis, rays, radius_m, settings, view_step.angle_deg) for image in images
    ]
    surface_m = _surface_height(views, axis)
    views = [
        _above(v, surface_m - BELOW_SURFACE_M, surface_m + settings.filters.pass_through_max_m)
        for v in views
    ]
    all_points = Cloud.concatenate([v.points for v in views])
    has_colour = all(i.capture.color is not None for i in images)
    exg = excess_green(all_points.colors)
    separation = choose_separation(exg if has_colour else None)
    threshold = otsu_threshold(exg) if not separation.by_geometry and len(exg) else np.inf
    plant = [_plant_mask(v, surface_m, separation, threshold) for v in views]
    refine = getattr(view_step, "nominal", None) is not None and settings.registration.enabled
    turns, report = _place_views(views, plant, axis, surface_m, refine, warnings)
    green = Cloud.concatenate(
        [
            v.points.select(m).transformed(axis.T_view0_view(turns[i]))
            for i, (v, m) in enumerate(zip(views, plant, strict=True))
        ]
    )
    soil = Cloud.concatenate(
        [_soil(v, surface_m).transformed(axis.T_view0_view(turns[i])) for i, v in enumerate(views)]
    )
    scan = StationScan(
        station,
        green,
        soil,
        [v.view for v in views],
        float(threshold) if np.isfinite(threshold) else 0.0,
        int(sum(int(np.isfinite(i.depth_m).sum()) for i in images)),
        separation,
    )
    report |= {"working_radius_m": radius_m, "kept_in_volume": len(all_points)}
    return TurntableScan(scan, _T_field_view0(axis, surface_m), report)


def _station_images(session: Session, warnings: list[str]) -> tuple[int, list[CaptureImages]]:
    grouped = captures_by_station(session)
    if not grouped:
        return 0, []
    station = session.calibration.stations.reference if session.calibration.stations else 0
    if station not in grouped:
        station = min(grouped)
    if len(grouped) > 1:
        others = ", ".join(str(s) for s in grouped if s != station)
        warnings.append(f"a turntable session has one station: stations {others} ignored")
    images = []
    for capture in grouped[station]:
        try:
            images.append(read_scan_capture(session, capture))
        except FormatError as error:
            warnings.append(f"station {station} view {capture.view} skipped: {error}")
    return station, images


def _in_volume(
    image: CaptureImages,
    axis: TableAxis,
    rays: NDArray[np.float64],
    radius_m: float,
    settings: ReconstructionSettings,
    step_deg: float,
) -> _View:
    """A view's points within ``radius_m`` of the axis (camera frame)."""
    capture = image.capture
    cloud = backproject(
        image.depth_m, image.color, rays, settings.crop.radius_m, settings.crop.min_depth_m
    )
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
        raise FieldappError("nothing near the turntable's axis: is view_step.matrix right?")
    bins = np.arange(near.min(), near.max() + 2 * SURFACE_BIN_M, SURFACE_BIN_M)
    counts, edges = np.histogram(near, bins=bins)
    peak = (edges[np.argmax(counts)] + edges[np.argmax(counts) + 1]) / 2.0
    return float(np.median(near[np.abs(near - peak) <= 2 * SURFACE_BIN_M]))


def _above(view: _View, low_m: float, high_m: float) -> _View:
    keep = (view.height_m >= low_m) & (view.height_m <= high_m)
    return _View(view.view, view.commanded_deg, view.points.select(keep), view.height_m[keep])


def _plant_mask(
    view: _View, surface_m: float, separation: Separation, threshold: float
) -> NDArray[np.bool_]:
    """Which of a view's points go on as plant candidates: all (geometry splits them after
    levelling) or the green ones."""
    if separation.by_geometry:
        return np.ones(len(view.points), dtype=bool)
    return excess_green(view.points.colors) > threshold


def _soil(view: _View, surface_m: float) -> Cloud:
    near = np.flatnonzero(np.abs(view.height_m - surface_m) <= BELOW_SURFACE_M)
    return view.points.select(near[::SOIL_STRIDE])


def _place_views(
    views: list[_View],
    plant: list[NDArray[np.bool_]],
    axis: TableAxis,
    surface_m: float,
    refine: bool,
    warnings: list[str],
) -> tuple[list[float], dict[str, object]]:
    """Each view's turn from view 0 (table degrees): the commanded steps, refined when
    ``refine`` by ICP about the axis: first each view against the views already placed, then
    (``ICP_ROUNDS`` times) each against all the others, view 0 staying put."""
    turns = [v.commanded_deg - views[0].commanded_deg for v in views]
    commanded = list(turns)
    if not refine:
        return turns, {"view_turns_deg": [round(t, 3) for t in turns], "refined_by_icp": False}
    points = [
        v.points.points[plant[i] & (v.height_m > surface_m + ICP_ABOVE_SURFACE_M)]
        for i, v in enumerate(views)
    ]
    failed: set[int] = set()
    for round_ in range(ICP_ROUNDS + 1):
        for i in range(1, len(views)):
            if round_ == 0:
                turns[i] = turns[i - 1] + commanded[i] - commanded[i - 1]
            others = range(i) if round_ == 0 else (j for j in range(len(views)) if j != i)
            target = np.concatenate(
                [transform_points(axis.T_view0_view(turns[j]), points[j]) for j in others]
            )
            correction = _icp_about_axis(points[i], target, axis, turns[i])
            if correction is None:
                failed.add(views[i].view)
            else:
                turns[i] += correction
    for i, turn in enumerate(turns):
        if abs(turn - commanded[i]) > MAX_REFINEMENT_DEG * 2:
            failed.add(views[i].view)
            turns[i] = commanded[i]
    if failed:
        warnings.append(
            f"views {', '.join(map(str, sorted(failed)))}: ICP about the table's axis failed; "
            "the commanded angles are kept"
        )
    return turns, {
        "view_turns_deg": [round(t, 3) for t in turns],
        "icp_corrections_deg": [round(t - c, 3) for t, c in zip(turns, commanded, strict=True)],
        "refined_by_icp": True,
    }


def _icp_about_axis(
    source_m: NDArray[np.float64], target_m: NDArray[np.float64], axis: TableAxis, turn_deg: float
) -> float | None:
    """The correction (table degrees) to ``turn_deg`` that best lays ``source_m`` (N, 3), a
    view's plant points in its camera frame, on ``target_m`` (M, 3) in view 0: the best of a
    search over +-``MAX_REFINEMENT_DEG``, then ICP with one degree of freedom (the turn about
    the axis), coarse to fine; ``None`` with too few points or pairs."""
    if len(source_m) < ICP_MIN_PAIRS or len(target_m) < ICP_MIN_PAIRS:
        return None
    tree = cKDTree(target_m)

    def cost(delta: float) -> float:
        moved = transform_points(axis.T_view0_view(turn_deg + delta), source_m)
        distance, _ = tree.query(moved, distance_upper_bound=ICP_DISTANCES_M[0])
        return float(np.mean(np.minimum(distance, ICP_DISTANCES_M[0])))

    candidates = np.arange(-MAX_REFINEMENT_DEG, MAX_REFINEMENT_DEG + 1e-9, SEARCH_STEP_DEG)
    delta = float(candidates[np.argmin([cost(c) for c in candidates])])
    for max_distance in ICP_DISTANCES_M:
        for _ in range(ICP_ITERATIONS):
            moved = transform_points(axis.T_view0_view(turn_deg + delta), source_m)
            distance, index = tree.query(moved, distance_upper_bound=max_distance)
            paired = np.isfinite(distance)
            if paired.sum() < ICP_MIN_PAIRS:
                return None
            s = _flat(moved[paired] - axis.point_m, axis.up)
            t = _flat(target_m[index[paired]] - axis.point_m, axis.up)
            phi = np.arctan2(np.sum(np.cross(s, t) @ axis.up), np.sum(s * t))
            step = float(phi) / axis.rad_per_deg
            delta += step
            if abs(step) < 1e-3:
                break
    return delta


def _flat(vectors: NDArray[np.float64], up: NDArray[np.float64]) -> NDArray[np.float64]:
    """``vectors`` (N, 3) without their component along ``up``."""
    return vectors - (vectors @ up)[:, None] * up


def _T_field_view0(axis: TableAxis, surface_m: float) -> Matrix4:
    """Field frame: z up the axis, origin on it at the soil surface, x along the camera's view."""
    ez = axis.up
    ex = np.array([0.0, 0.0, 1.0]) - ez[2] * ez
    ex /= np.linalg.norm(ex)
    R = np.stack([ex, np.cross(ez, ex), ez])
    origin = axis.point_m + surface_m * axis.up
    return make_transform(R, -R @ origin)
