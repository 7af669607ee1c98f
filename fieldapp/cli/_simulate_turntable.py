"""``fieldapp simulate --scene turntable``: a plant turning on a turntable before a fixed camera.

One station (1), ``views`` captures, the room standing still behind the plant. The session
says ``"turntable": {"carries": "plant", "working_radius_m": ...}`` (see
``docs/RECONSTRUCTION.md``, "Plant on a turntable"); the calibration holds the intrinsics and
the *nominal* view step (the table's commanded step about an axis measured by tape, marked
``nominal``: no board was seen), and the captures the commanded angles; the table really
stopped up to a degree or two off them (in ``truth.json``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from devices.camera.frames import KINECT_V2_PAPER
from devices.sim.turntable_scene import (
    WORKING_RADIUS_M,
    TurntableRig,
    plant_truth,
    turntable_captures,
    turntable_plant,
)
from fieldapp.io.calibration import CALIBRATION_FORMAT, Calibration, DepthCamera, Stations, ViewStep
from fieldapp.io.durable import write_json_durably
from fieldapp.io.writer import SessionWriter

STATION = 1


def turntable_calibration(rig: TurntableRig) -> Calibration:
    """Intrinsics and the nominal view step of ``rig``; one station, its own reference."""
    k = KINECT_V2_PAPER
    view_step = ViewStep(angle_deg=rig.view_step_deg, matrix=rig.T_view_next())
    view_step.nominal = (
        f"simulated: plant turning {rig.view_step_deg:g} degrees about the table's axis "
        f"{rig.distance_m:g} m before the camera; no board"
    )
    return Calibration(
        format=CALIBRATION_FORMAT,
        depth_camera=DepthCamera(
            width=k.width, height=k.height, fx=k.fx, fy=k.fy, cx=k.cx, cy=k.cy
        ),
        view_step=view_step,
        stations=Stations(
            reference=STATION,
            to_reference={STATION: [[float(i == j) for j in range(4)] for i in range(4)]},
        ),
    )


def write_turntable_session(
    folder: Path,
    seed: int,
    day: int,
    views: list[int],
    depth_only: bool,
    rig: TurntableRig | None = None,
    color_holes: bool = False,
    color_noise: float | None = None,
) -> int:
    """Simulate and write the session and its truth; returns the number of captures.
    ``color_holes``: colour black where libfreenect2's registration gives none
    (:func:`devices.sim.sensor.registered_as_libfreenect2`); ``color_noise``: each colour
    channel's own noise, levels (``SensorModel.color_noise``)."""
    from devices.sim.render import SensorModel
    from devices.sim.sensor import registered_as_libfreenect2

    rig = rig or TurntableRig()
    plant = turntable_plant(seed, day)
    about: dict[str, Any] = {"scene": "turntable", "seed": seed, "day": day}
    about |= {"depth_only": depth_only} | ({"color_holes": True} if color_holes else {})
    if color_noise is not None:  # absent: brightness noise only (sessions unchanged)
        about["color_noise_levels"] = color_noise
    sensor = SensorModel(color_noise=color_noise or 0.0)
    writer = SessionWriter.create(
        folder,
        f"sim-turntable-seed{seed}-day{day}",
        turntable_calibration(rig),
        extra={
            "simulated": about,
            "turntable": {"carries": "plant", "working_radius_m": WORKING_RADIUS_M},
        },
    )
    truths: list[dict[str, Any]] = []
    for capture in turntable_captures(plant, rig, views, seed, sensor=sensor):
        frame = capture.frame
        color = None if depth_only else frame.color
        if color is not None and color_holes:
            color = registered_as_libfreenect2(color, frame.depth_m, KINECT_V2_PAPER)
        writer.add_capture(
            STATION,
            capture.view,
            frame.depth_m,
            color,
            ir=frame.ir,
            angle_deg=capture.reported_angle_deg,
        )
        truths.append(
            {"station": STATION, "view": capture.view, "angle_deg": capture.true_angle_deg}
        )
    truth = plant_truth(plant)
    write_json_durably(
        folder / "truth.json",
        {
            "format": "fieldapp-sim-truth/1",
            **about,
            "frame": "table: z up along the axis, z = 0 on the tray's soil, table at 0 degrees",
            "plants": [
                {
                    "name": truth.name,
                    "x_m": truth.x_m,
                    "y_m": truth.y_m,
                    "z_m": truth.z_m,
                    "height_cm": truth.height_cm,
                    "width_cm": truth.width_cm,
                }
            ],
            "T_table_camera": rig.T_table_camera.tolist(),
            "working_radius_m": WORKING_RADIUS_M,
            "captures": truths,
        },
    )
    return len(truths)
