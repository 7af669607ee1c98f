"""The calibration in force for a mission: the plan's file, or the simulated rig's nominal one.

The calibration must join what the plan captures: its view step is the plan's, and it names
the plan's reference station and every planned station.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import TYPE_CHECKING

from fieldapp.errors import FieldappError
from fieldapp.io.calibration import Calibration, load_calibration
from fieldapp.mission.plan import MissionPlan

if TYPE_CHECKING:
    from devices.sim.rig import Pose2D
    from devices.sim.world import SimWorld

log = logging.getLogger(__name__)


def calibration_in_force(plan: MissionPlan, world: SimWorld | None) -> Calibration:
    """``plan.calibration`` loaded and checked against the plan; without one, the nominal
    calibration of the simulated ``world`` (raises :class:`FieldappError` when there is none)."""
    if plan.calibration is not None:
        calibration = load_calibration(plan.calibration)
        check_against_plan(calibration, plan, str(plan.calibration))
        return calibration
    if world is None or plan.devices.camera_backend != "sim":
        raise FieldappError(
            "plan.calibration: no calibration file given, and the camera is real. Calibrate the "
            "rig (`fieldapp calibrate ...`) and name the file in the plan's calibration field"
        )
    return nominal_calibration(plan, world)


def rig_calibration(
    world: SimWorld, poses: Mapping[int, Pose2D], reference: int, step_deg: float
) -> Calibration:
    """The simulated rig's pre-calibration: the exact view step, each station from its map pose
    on level ground, ground = the reference station's nominal camera in the field frame."""
    from devices.geometry import invert
    from fieldapp.io.calibration import DepthCamera, Ground, Stations, ViewStep

    rig = world.rig
    nominal = {station: rig.T_field_camera(pose, 0.0) for station, pose in poses.items()}
    T_field_reference = nominal[reference]
    return Calibration(
        format="fieldapp-calibration/1",
        depth_camera=DepthCamera.from_intrinsics(world.intrinsics),
        view_step=ViewStep(angle_deg=step_deg, matrix=rig.T_camera0_camera(step_deg)),
        stations=Stations(
            reference=reference,
            to_reference={s: invert(T_field_reference) @ T for s, T in nominal.items()},
        ),
        ground=Ground(matrix=T_field_reference),
    )


def nominal_calibration(plan: MissionPlan, world: SimWorld) -> Calibration:
    """The simulated rig's pre-calibration for the plan's stations."""
    from devices.sim.rig import Pose2D

    poses = {s.number: Pose2D(s.x_m, s.y_m, s.yaw_deg) for s in plan.stations}
    return rig_calibration(world, poses, plan.reference_station, plan.views.step_deg)


def check_against_plan(calibration: Calibration, plan: MissionPlan, source: str) -> None:
    """Raise :class:`FieldappError` when ``calibration`` cannot join the plan's captures."""
    if calibration.view_step is None or calibration.stations is None:
        raise FieldappError(
            f"{source}: the calibration lacks its view step or stations; finish calibrating "
            "the rig (`fieldapp calibrate views` and `stations`)"
        )
    if abs(calibration.view_step.angle_deg - plan.views.step_deg) > 1e-6:
        raise FieldappError(
            f"{source}: view_step.angle_deg is {calibration.view_step.angle_deg:g}, the plan "
            f"turns {plan.views.step_deg:g} deg per view: use one or the other"
        )
    if calibration.stations.reference != plan.reference_station:
        raise FieldappError(
            f"{source}: reference station is {calibration.stations.reference}, the plan's is "
            f"{plan.reference_station}"
        )
    uncalibrated = sorted(set(plan.station_numbers()) - set(calibration.stations.to_reference))
    if uncalibrated:
        raise FieldappError(
            f"{source}: stations {uncalibrated} of the plan are not calibrated "
            "(stations.to_reference); calibrate them or drop them from the plan"
        )
