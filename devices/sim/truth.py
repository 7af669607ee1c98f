"""``truth.json``: what was really there and where the camera really stood.

Issue 3's fields (``plants``, ``spheres``, ``T_field_camera`` of view 0 of every station; plants
also at ``map_x_m``/``map_y_m`` in the base's map frame, with the plants they are ``touching``
and those whose space they are ``reaching_into``, and the organ truth of
:mod:`devices.sim.organ_truth`: ``stem_diameter_mm``, ``leaf_count``, ``leaf_area_cm2`` and
``leaves``, one entry per leaf) plus
``boards`` (geometry, pose, corners), ``captures`` (true pose and angle of every capture),
``stations`` (each station's nominal and true base pose in the map frame and its arrival error),
``intrinsics`` and the rig's nominal geometry.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import asdict
from typing import Any

from devices.camera.frames import Intrinsics
from devices.geometry import Matrix4, invert
from devices.sim.boards import PlacedBoard
from devices.sim.rig import RigGeometry
from devices.sim.scene import Scene

TRUTH_FORMAT = "fieldapp-sim-truth/1"


def board_truth(placed: PlacedBoard) -> dict[str, Any]:
    """A board's geometry, pose (``T_field_board``) and inner corners (field frame, OpenCV
    order)."""
    board = placed.board
    return {
        "name": board.name,
        "inner_cols": board.inner_cols,
        "inner_rows": board.inner_rows,
        "square_m": board.square_m,
        "margin_squares": board.margin_squares,
        "T_field_board": placed.T_field_board.tolist(),
        "corners_field_m": placed.corners_field_m.tolist(),
    }


def station_truth(captures: list[dict[str, Any]], rig: RigGeometry) -> dict[str, Any]:
    """Per station (key: its number as text): ``nominal_pose`` and ``true_pose`` of the base (map
    frame, x/y metres, yaw degrees) and ``arrival_error`` (true minus nominal)."""
    stations: dict[str, Any] = {}
    for capture in captures:
        key = str(capture["station"])
        if key in stations:
            continue
        nominal = rig.station_pose(capture["station"])
        true = capture["base_pose"]
        stations[key] = {
            "nominal_pose": {"x": nominal.x_m, "y": nominal.y_m, "yaw_deg": nominal.yaw_deg},
            "true_pose": dict(true),
            "arrival_error": {
                "x_m": true["x"] - nominal.x_m,
                "y_m": true["y"] - nominal.y_m,
                "yaw_deg": true["yaw_deg"] - nominal.yaw_deg,
            },
        }
    return dict(sorted(stations.items(), key=lambda item: int(item[0])))


def _map_xy(T_map_field: Matrix4, x_m: float, y_m: float) -> dict[str, float]:
    """``map_x_m``, ``map_y_m``: a field position in the base's map frame (where the
    reconstruction reports plants of a session whose captures carry base poses)."""
    x, y, _, _ = T_map_field @ [x_m, y_m, 0.0, 1.0]
    return {"map_x_m": float(x), "map_y_m": float(y)}


def truth_document(
    scene: Scene,
    captures: Iterable[dict[str, Any]],
    rig: RigGeometry,
    intrinsics: Intrinsics,
    about: dict[str, Any],
) -> dict[str, Any]:
    """The truth of a simulated session. ``captures``: :meth:`SimCapture.truth` of each capture;
    ``about`` (scene name, seed, day...) is kept as is."""
    captures = list(captures)
    T_map_field = invert(rig.T_field_map)
    contacts = scene.contacts() if scene.plants else None
    view0 = {
        str(c["station"]): c["T_field_camera"]
        for c in captures
        if c["view"] == 0 and c["target"] is None
    }
    return {
        "format": TRUTH_FORMAT,
        **about,
        "plants": [
            {
                "name": p.name,
                "x_m": p.x_m,
                "y_m": p.y_m,
                "z_m": p.z_m,
                "height_cm": p.height_cm,
                "width_cm": p.width_cm,
                **_map_xy(T_map_field, p.x_m, p.y_m),
                "leaf_count": p.leaves,
                "touching": contacts.touching[p.name] if contacts else [],
                "reaching_into": contacts.reaching_into[p.name] if contacts else [],
                **(p.organs or {}),
            }
            for p in scene.plants
        ],
        "spheres": [
            {"name": s.name, "x_m": s.x_m, "y_m": s.y_m, "z_m": s.z_m, "diameter_mm": s.diameter_mm}
            for s in scene.spheres
        ],
        "boards": [board_truth(b) for b in scene.boards],
        "T_field_camera": view0,
        "stations": station_truth(captures, rig),
        "captures": captures,
        "intrinsics": asdict(intrinsics),
        "rig": {**asdict(rig), "T_field_map": rig.T_field_map.tolist()},
    }
