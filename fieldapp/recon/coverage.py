"""Which plants the captures covered as planned.

The stations stand so that every plant has one nearby that turns all the way round: its leaves
are seen close up and from every side. When the station nearest a plant has no usable capture
(a mission cut short, a station skipped) or turned through fewer views than a full turn, the
plant was seen only from farther stations or from fewer sides, and its height and width may
come out low: on a simulated plot captured from 4 of its 9 stations, the plant in the far
corner measured 17.8 cm wide for 41.9 and 5.8 cm short (others so placed came out within 1 cm).
Such plants are named in the warnings, so that no one takes their traits for as sure as the
others'.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4


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


def coverage_warnings(
    plants_xy: Mapping[int, NDArray[np.float64]],
    stations_xy: Mapping[int, NDArray[np.float64]],
    views_read: Mapping[int, int],
    views_per_turn: int,
) -> list[str]:
    """One warning for the plants (id -> (2,) position) whose nearest station (id -> (2,))
    has no usable capture (not in ``views_read``: station -> views read), one for those whose
    nearest station turned through fewer than ``views_per_turn`` views."""
    if not plants_xy or not stations_xy:
        return []
    ids = list(stations_xy)
    at = np.array([stations_xy[s] for s in ids])
    unseen: list[str] = []
    partial: list[str] = []
    for plant, xy in plants_xy.items():
        distance = np.hypot(*(at - xy).T)
        station = ids[int(np.argmin(distance))]
        if station not in views_read:
            read = [i for i, s in enumerate(ids) if s in views_read]
            nearest_read = float(distance[read].min()) if read else float("nan")
            unseen.append(f"{plant} (station {station}; nearest read {nearest_read:.1f} m)")
        elif views_read[station] < views_per_turn:
            partial.append(f"{plant} (station {station}: {views_read[station]} views)")
    warnings = []
    if unseen:
        warnings.append(
            f"plants seen only from farther stations, their traits may be low: the station "
            f"nearest each has no usable capture: plant {', plant '.join(unseen)}"
        )
    if partial:
        warnings.append(
            f"plants seen from fewer sides, their traits may be low: the station nearest each "
            f"turned through fewer than {views_per_turn} views: plant {', plant '.join(partial)}"
        )
    return warnings
