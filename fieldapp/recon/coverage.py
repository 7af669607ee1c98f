"""Which plants the captures covered as planned.

The stations stand so that every plant has one nearby that turns all the way round: its leaves
are seen close up and from every side. When the station nearest a plant has no usable capture
(a mission cut short, a station skipped) or turned through fewer views than a full turn, the
plant was seen only from farther stations or from fewer sides, and its height and width may
come out low: on a simulated plot captured from 4 of its 9 stations, the plant in the far
corner measured 17.8 cm wide for 41.9 and 5.8 cm short (others so placed came out within 1 cm).
Such plants are named in the warnings, so that no one takes their traits for as sure as the
others'.

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

from devices.geometry import Matrix4
from fieldapp.io.calibration import DepthCamera

CEILING_MARGIN_M = 0.02
"""A plant whose highest point is within this of the views' ceiling above it may be cut."""


def station_axes_xy(
    T_out_station: Mapping[int, Matrix4],
    to_reference: Mapping[int, Matrix4],
    reference: int,
    axis_point: NDArray[np.float64],
) -> dict[int, NDArray[np.float64]]:
    """(2,) where each calibrated station's turntable axis (``axis_point`` (3,), in its view-0
    frame) stands in the output frame: from its registered pose ``T_out_station`` when it was
    read, else from the reference's by the station calibration ``to_reference``."""
    anchor = T_out_station[reference]
    where: dict[int, NDArray[np.float64]] = {}
    for station, T_reference_station in to_reference.items():
        T = T_out_station.get(station)
        T = anchor @ T_reference_station if T is None else T
        where[station] = (T[:3, :3] @ axis_point + T[:3, 3])[:2]
    return where


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
TALLER = "taller"
HEADINGS = {
    FARTHER: "plants seen only from farther stations, their traits may be low: the station "
    "nearest each has no usable capture",
    FEWER_SIDES: "plants seen from fewer sides, their traits may be low: the station nearest "
    "each turned through fewer than {views} views",
    TALLER: "plants that may be taller than measured: their highest point lies where the views "
    "stop seeing",
}
NOTES = {
    FARTHER: "seen only from farther stations, traits may be low",
    FEWER_SIDES: "seen from fewer sides, traits may be low",
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
    camera: DepthCamera,
    radius_m: float,
    min_depth_m: float,
) -> float:
    """The highest point above ``xy_m`` (2,) (output frame, z up) that one of the views whose
    poses are ``T_out_camera`` (V, 4, 4) sees: where the vertical through it leaves the image
    at its top edge (OpenCV camera: y down the image), the crop sphere of ``radius_m`` around
    the camera, or comes nearer than ``min_depth_m`` (a camera looking down: going up the
    vertical comes nearer), whichever comes first, on an image column; -inf when no view sees
    up that vertical."""
    R, C = T_out_camera[:, :3, :3], T_out_camera[:, :3, 3]
    ground = np.array([xy_m[0], xy_m[1], 0.0])
    a = np.einsum("vji,vj->vi", R, ground - C)  # the vertical's foot in each camera's frame
    b = R[:, 2, :]  # the vertical's direction (world z) in each camera's frame
    k = camera.cy / camera.fy
    rising = b[:, 1] + k * b[:, 2]  # how the top edge's test changes going up the vertical
    with np.errstate(divide="ignore", invalid="ignore"):
        z_edge = np.where(rising < 0.0, -(a[:, 1] + k * a[:, 2]) / rising, np.inf)
        across = np.hypot(*(ground[:2] - C[:, :2]).T)
        z_sphere = C[:, 2] + np.sqrt(np.maximum(radius_m**2 - across**2, 0.0))
        z_near = np.where(b[:, 2] < 0.0, (min_depth_m - a[:, 2]) / b[:, 2], np.inf)
    z = np.minimum(np.minimum(z_edge, z_near), np.where(across < radius_m, z_sphere, -np.inf))
    q = a + z[:, None] * b
    with np.errstate(divide="ignore", invalid="ignore"):
        u = camera.fx * q[:, 0] / q[:, 2] + camera.cx
        v = camera.fy * q[:, 1] / q[:, 2] + camera.cy
    seen = np.isfinite(z) & (q[:, 2] >= min_depth_m - 1e-9) & (u >= 0.0) & (u <= camera.width)
    seen &= (v >= -1e-6) & (v <= camera.height) & (np.linalg.norm(q, axis=1) <= radius_m + 1e-9)
    return float(z[seen].max()) if seen.any() else float("-inf")


def cut_tops(
    tops_m: Mapping[int, NDArray[np.float64]],
    T_out_camera: NDArray[np.float64],
    camera: DepthCamera,
    radius_m: float,
    min_depth_m: float,
    pass_through_max_m: float,
) -> dict[int, Caution]:
    """The plants (id -> (3,) highest point) whose highest point lies within
    :data:`CEILING_MARGIN_M` of the ceiling above it: the highest any view sees there
    (:func:`view_ceiling_m`), or the filters' pass-through limit."""
    cautions = {}
    for plant, top in tops_m.items():
        seen = view_ceiling_m(top[:2], T_out_camera, camera, radius_m, min_depth_m)
        ceiling = min(seen, pass_through_max_m)
        if top[2] >= ceiling - CEILING_MARGIN_M:
            detail = f"top {100 * top[2]:.0f} cm, views reach {100 * ceiling:.0f} cm"
            cautions[plant] = Caution(TALLER, detail)
    return cautions
