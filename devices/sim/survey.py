"""A simulated mission: the base visits stations, the table turns through its views, the camera
captures; every capture carries what the devices reported and what was really true.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from devices.camera.frames import Frame
from devices.geometry import Matrix4
from devices.sim.rig import Pose2D, StopErrors
from devices.sim.world import SimWorld


@dataclass(frozen=True)
class SimCapture:
    """One capture. ``reported_*`` is what the base and table said; ``true_*`` and
    ``T_field_camera`` are where they really stood. ``target`` names the calibration board the
    capture was taken for (``None`` for a plain capture)."""

    station: int
    view: int
    target: str | None
    frame: Frame
    reported_pose: Pose2D
    reported_angle_deg: float
    true_pose: Pose2D
    true_angle_deg: float
    T_field_camera: Matrix4

    def truth(self) -> dict[str, Any]:
        """The capture's truth as JSON-ready data."""
        return {
            "station": self.station,
            "view": self.view,
            "target": self.target,
            "angle_deg": self.true_angle_deg,
            "base_pose": {
                "x": self.true_pose.x_m,
                "y": self.true_pose.y_m,
                "yaw_deg": self.true_pose.yaw_deg,
            },
            "T_field_camera": self.T_field_camera.tolist(),
        }


def survey(
    world: SimWorld,
    stations: Sequence[int],
    views: Sequence[int],
    seed: int,
    errors: StopErrors | None = None,
    tag_boards: bool = False,
) -> Iterator[SimCapture]:
    """Visit ``stations`` in order and capture ``views`` at each, deterministically for ``seed``.

    With ``tag_boards``, every (station, view) that sees a board of the scene whole is captured
    once more for it (a fresh shot, ``target`` = the board's name).
    """
    errors = errors or StopErrors()
    step_deg = world.rig.view_step_deg
    for station in stations:
        rng = np.random.default_rng([seed, 17, station])
        reported, true = errors.base_stop(world.rig.station_pose(station), rng)
        world.set_base_pose(true.x_m, true.y_m, true.yaw_deg)
        for view in views:
            target_deg = view * step_deg
            true_angle = errors.table_stop(target_deg, rng)
            world.set_table_angle_deg(true_angle)
            T = world.T_field_camera()
            shots: list[str | None] = [None]
            if tag_boards:
                shots += world.boards_in_view()
            for shot, target in enumerate(shots):
                frame = world.render(np.random.default_rng([seed, 19, station, view, shot]))
                yield SimCapture(
                    station,
                    view,
                    target,
                    frame,
                    reported,
                    errors.table_report(target_deg, true_angle),
                    true,
                    true_angle,
                    T,
                )
