"""Which plants the captures covered as planned.

The stations stand so that every plant has one nearby that turns all the way round: its leaves
are seen close up and from every side. When the station nearest a plant has no usable capture
(a mission cut short, a station skipped) or turned through fewer views than a full turn, the
plant was seen only from farther stations or from fewer sides, and its height and width may
come out low: on a simulated plot captured from 4 of its 9 stations, the plant in the far
corner measured 17.8 cm wide for 41.9 and 5.8 cm short (others so placed came out within 1 cm).
Such plants are named in the warnings, so that no one takes their traits for as sure as the
others'.

A plant near a station is seen close up only on that station's side: the cameras look down
and outwards, and the side of the plant away from them is seen from the next stations. When
those are not read, the plant was seen from one side only although its nearest station turned
all the way: on the 3 x 3 plot captured from its four corner stations, the plants 0.5 m from
the corners measured 25 cm wide for 50, 28 for 39 and 34 for 41. A plant is named when the
views read leave it unseen over more than half a turn (:data:`ONE_SIDE_DEG`: no camera in a
half-plane round it, :func:`unseen_arc_deg`) where the planned views would not have.

On the paper's rig the cameras look down at 45 degrees from 1.3 m: above a point a metre away
they see up to about 1 m, and nothing above 1.5 m passes the filters. A plant taller than what
any view sees above it is measured at that ceiling: simulated day-60 plants of 103-130 cm came
out 103-114 cm with no flag. A plant whose highest point lies within :data:`CEILING_MARGIN_M`
of the highest any view sees above that spot (:func:`view_ceiling_m`) is named too.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4, invert
from fieldapp.io.calibration import DepthCamera

CEILING_MARGIN_M = 0.02
"""A plant whose highest point is within this of the views' ceiling above it may be cut."""
ONE_SIDE_DEG = 180.0
"""A plant no view saw from an arc of more than this round it was seen from one side."""


def station_poses(
    T_out_station: Mapping[int, Matrix4],
    to_reference: Mapping[int, Matrix4],
    reference: int,
) -> dict[int, Matrix4]:
    """Each calibrated station's pose in the output frame: ``T_out_station`` when it was
    read, else by the station calibration ``to_reference`` from ``reference``'s (a station
    read: the plot's anchor, which is not the calibration's reference when that was not
    read)."""
    T_out_reference = T_out_station[reference] @ invert(to_reference[reference])
    return {
        station: T_out_station.get(station, T_out_reference @ T_reference_station)
        for station, T_reference_station in to_reference.items()
    }


def station_axes_xy(
    T_out_station: Mapping[int, Matrix4],
    to_reference: Mapping[int, Matrix4],
    reference: int,
    axis_point: NDArray[np.float64],
) -> dict[int, NDArray[np.float64]]:
    """(2,) where each calibrated station's turntable axis (``axis_point`` (3,), in its view-0
    frame) stands in the output frame (poses: :func:`station_poses`)."""
    poses = station_poses(T_out_station, to_reference, reference)
    return {station: (T[:3, :3] @ axis_point + T[:3, 3])[:2] for station, T in poses.items()}


@dataclass(frozen=True)
class ViewLimits:
    """What a view sees of the points in its image: those no nearer than ``min_depth_m``
    along its axis (the sensor's near limit) and within ``radius_m`` of it (the crop)."""

    camera: DepthCamera
    radius_m: float
    min_depth_m: float


@dataclass(frozen=True)
class Caution:
    """Why one plant's traits are less sure than the others': ``kind`` (one of
    :data:`FARTHER`, :data:`FEWER_SIDES`, :data:`TALLER`) and the plant's figures."""

    kind: str
    detail: str

    def note(self) -> str:
        """The caution as one line for the plant's entry in ``report.json``."""
        return f"{NOTES[self.kind]} ({self.detail})"


FARTHER = "farther"
FEWER_SIDES = "fewer sides"
ONE_SIDE = "one side"
TALLER = "taller"
HEADINGS = {
    FARTHER: "plants seen only from farther stations, their traits may be low: the station "
    "nearest each has no usable capture",
    FEWER_SIDES: "plants seen from fewer sides, their traits may be low: the station nearest "
    "each turned through fewer than {views} views",
    ONE_SIDE: "plants seen from one side only, their traits may be low: the views read leave "
    "more than half a turn round each unseen, the planned views would not",
    TALLER: "plants that may be taller than measured: their highest point lies where the views "
    "stop seeing",
}
NOTES = {
    FARTHER: "seen only from farther stations, traits may be low",
    FEWER_SIDES: "seen from fewer sides, traits may be low",
    ONE_SIDE: "seen from one side only, traits may be low",
    TALLER: "may be taller than measured: its top is where the views stop seeing",
}


def uncovered(
    plants_xy: Mapping[int, NDArray[np.float64]],
    stations_xy: Mapping[int, NDArray[np.float64]],
    views_read: Mapping[int, int],
    views_per_turn: int,
) -> dict[int, Caution]:
    """The plants (id -> (2,) position) whose nearest station (id -> (2,)) has no usable
    capture (not in ``views_read``: station -> views read) or turned through fewer than
    ``views_per_turn`` views."""
    if not stations_xy:
        return {}
    ids = list(stations_xy)
    at = np.array([stations_xy[s] for s in ids])
    read = [i for i, s in enumerate(ids) if s in views_read]
    cautions: dict[int, Caution] = {}
    for plant, xy in plants_xy.items():
        distance = np.hypot(*(at - xy).T)
        station = ids[int(np.argmin(distance))]
        if station not in views_read:
            nearest_read = float(distance[read].min()) if read else float("nan")
            detail = f"station {station}; nearest read {nearest_read:.1f} m"
            cautions[plant] = Caution(FARTHER, detail)
        elif views_read[station] < views_per_turn:
            cautions[plant] = Caution(
                FEWER_SIDES, f"station {station}: {views_read[station]} views"
            )
    return cautions


def seeing(
    point_m: NDArray[np.float64],
    T_out_camera: NDArray[np.float64],
    limits: ViewLimits,
) -> NDArray[np.bool_]:
    """(V,) which of the views whose poses are ``T_out_camera`` (V, 4, 4) (OpenCV cameras)
    see ``point_m`` (3,) within their ``limits`` (occlusion aside)."""
    R, C = T_out_camera[:, :3, :3], T_out_camera[:, :3, 3]
    q = np.einsum("vji,vj->vi", R, point_m - C)  # in each camera's frame
    camera = limits.camera
    with np.errstate(divide="ignore", invalid="ignore"):
        u = camera.fx * q[:, 0] / q[:, 2] + camera.cx
        v = camera.fy * q[:, 1] / q[:, 2] + camera.cy
    inside = (u >= 0.0) & (u <= camera.width) & (v >= 0.0) & (v <= camera.height)
    near = (q[:, 2] >= limits.min_depth_m) & (np.linalg.norm(q, axis=1) <= limits.radius_m)
    return inside & near  # type: ignore[no-any-return]


def unseen_arc_deg(
    point_m: NDArray[np.float64],
    T_out_camera: NDArray[np.float64],
    limits: ViewLimits,
) -> float:
    """The widest arc round ``point_m`` (3,) (plan view, degrees) with none of the cameras
    that see it (:func:`seeing`) in it: 0 when they surround it closely, over 180 when they
    all stand on one side, 360 when none sees it."""
    looking = seeing(point_m, T_out_camera, limits)
    if not looking.any():
        return 360.0
    towards = T_out_camera[looking, :2, 3] - point_m[:2]
    azimuths = np.sort(np.degrees(np.arctan2(towards[:, 1], towards[:, 0])) % 360.0)
    return float(np.diff(np.append(azimuths, azimuths[0] + 360.0)).max())


def one_sided(
    centres_m: Mapping[int, NDArray[np.float64]],
    planned: NDArray[np.float64],
    read: NDArray[np.float64],
    limits: ViewLimits,
) -> dict[int, Caution]:
    """The plants (id -> (3,) centre) that the ``read`` views (V, 4, 4) leave unseen over more
    than :data:`ONE_SIDE_DEG` round them while the ``planned`` ones (P, 4, 4) would not
    (:func:`unseen_arc_deg`)."""
    cautions = {}
    for plant, centre in centres_m.items():
        arc = unseen_arc_deg(centre, read, limits)
        if arc <= ONE_SIDE_DEG:
            continue
        plan = unseen_arc_deg(centre, planned, limits)
        if plan <= ONE_SIDE_DEG:
            detail = f"unseen over {arc:.0f} deg round it, {plan:.0f} as planned"
            cautions[plant] = Caution(ONE_SIDE, detail)
    return cautions


def grouped_warnings(cautions: Iterable[tuple[int, Caution]], views_per_turn: int) -> list[str]:
    """One warning per kind of caution (plant id, caution), naming its plants in order, each
    with its figures."""
    ordered = sorted(cautions, key=lambda item: item[0])
    warnings = []
    for kind, heading in HEADINGS.items():
        named = [f"{plant} ({c.detail})" for plant, c in ordered if c.kind == kind]
        if named:
            heading = heading.format(views=views_per_turn)
            warnings.append(f"{heading}: plant {', plant '.join(named)}")
    return warnings


def view_ceiling_m(
    xy_m: NDArray[np.float64],
    T_out_camera: NDArray[np.float64],
    limits: ViewLimits,
) -> float:
    """The highest point above ``xy_m`` (2,) (output frame, z up, from the ground at 0) that
    one of the views whose poses are ``T_out_camera`` (V, 4, 4) sees: each view sees the
    stretch of that vertical inside its image (any of the four edges may end it: a vertical
    is not an image column) and within its ``limits`` (a camera looking down: going up the
    vertical comes nearer); the top of the highest stretch, or -inf when no view sees any."""
    camera, radius_m = limits.camera, limits.radius_m
    R, C = T_out_camera[:, :3, :3], T_out_camera[:, :3, 3]
    ground = np.array([xy_m[0], xy_m[1], 0.0])
    a = np.einsum("vji,vj->vi", R, ground - C)  # the vertical's foot in each camera's frame
    b = R[:, 2, :]  # the vertical's direction (world z) in each camera's frame, unit
    # each bound as c . q + d >= 0 on q = a + z b: u >= 0, u <= width, v >= 0, v <= height
    # (times the depth, positive where the near limit holds) and the near limit itself
    c = np.array(
        [
            [camera.fx, 0.0, camera.cx],
            [-camera.fx, 0.0, camera.width - camera.cx],
            [0.0, camera.fy, camera.cy],
            [0.0, -camera.fy, camera.height - camera.cy],
            [0.0, 0.0, 1.0],
        ]
    )
    d = np.array([0.0, 0.0, 0.0, 0.0, -limits.min_depth_m])
    at_foot, rate = a @ c.T + d, b @ c.T  # (V, 5): each bound's value at z = 0, its slope
    with np.errstate(divide="ignore", invalid="ignore"):
        crossing = -at_foot / rate
    low = np.where(rate > 0.0, crossing, -np.inf).max(axis=1, initial=0.0)  # from the ground
    high = np.where(rate < 0.0, crossing, np.inf).min(axis=1)
    never = ((rate == 0.0) & (at_foot < 0.0)).any(axis=1)
    along = np.einsum("vi,vi->v", a, b)  # the crop sphere: |a + z b| <= radius_m
    spread = along**2 - np.einsum("vi,vi->v", a, a) + radius_m**2
    root = np.sqrt(np.maximum(spread, 0.0))
    low, high = np.maximum(low, -along - root), np.minimum(high, -along + root)
    seen = ~never & (spread >= 0.0) & (low <= high)
    return float(high[seen].max()) if seen.any() else float("-inf")


def cut_tops(
    tops_m: Mapping[int, NDArray[np.float64]],
    T_out_camera: NDArray[np.float64],
    limits: ViewLimits,
    pass_through_max_m: float,
) -> dict[int, Caution]:
    """The plants (id -> (3,) highest point) whose highest point lies within
    :data:`CEILING_MARGIN_M` of the ceiling above it: the highest any view sees there
    (:func:`view_ceiling_m`), or the filters' pass-through limit."""
    cautions = {}
    for plant, top in tops_m.items():
        seen = view_ceiling_m(top[:2], T_out_camera, limits)
        # no view's stretch of that vertical (its top seen, yet off every view by the
        # poses): nothing to judge it by but the filters' limit
        ceiling = pass_through_max_m if seen == float("-inf") else min(seen, pass_through_max_m)
        if top[2] >= ceiling - CEILING_MARGIN_M:
            detail = f"top {100 * top[2]:.0f} cm, views reach {100 * ceiling:.0f} cm"
            cautions[plant] = Caution(TALLER, detail)
    return cautions
