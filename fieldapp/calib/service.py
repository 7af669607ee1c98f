"""One calibration service for the command line and the wizards.

Each calibration is the same four steps, whoever presents it: the calibration in force is
loaded (:func:`in_force`), the solver runs (the ``*_job`` functions return it ready to run on a
worker), its result is judged (:mod:`fieldapp.calib.verdict`) and merged as a new section with
its provenance into the calibration (the ``merge_*`` functions), which is saved with the
previous file kept beside it (:func:`save`). The callers only present the figures.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from devices.geometry import rotation_angle_deg
from fieldapp.calib.board import Board
from fieldapp.calib.ground import GroundResult, calibrate_ground
from fieldapp.calib.intrinsics import IntrinsicsResult, SolveOptions
from fieldapp.calib.stations import StationsResult, calibrate_stations
from fieldapp.calib.store import provenance, save_keeping_previous
from fieldapp.calib.views import ViewStepResult
from fieldapp.errors import FieldappError
from fieldapp.io.calibration import (
    CALIBRATION_FORMAT,
    Calibration,
    DepthCamera,
    Ground,
    StationPose,
    Stations,
    ViewStep,
    load_calibration,
)
from fieldapp.io.session import Session
from fieldapp.recon.settings import ReconstructionSettings

NOMINAL_STEP_DEG = 45.0
"""The view step assumed when a session's calibration has none (eight views a turn)."""


def in_force(path: Path) -> Calibration | None:
    """The calibration file at ``path`` as it is now, None when there is none.

    Raises FormatError when it exists but is not a valid calibration file."""
    return load_calibration(path) if path.exists() else None


def save(path: Path, calibration: Calibration) -> Path | None:
    """Write ``calibration`` to ``path`` durably, the previous file kept beside it (its path
    returned). Raises FieldappError naming the file when it cannot be written."""
    try:
        return save_keeping_previous(path, calibration)
    except OSError as error:
        raise FieldappError(f"{path}: cannot write ({error.strerror})") from None


def fixed_names(options: SolveOptions | None) -> list[str]:
    """The parameters a Zhang solve kept fixed, by name."""
    if options is None:
        return []
    fixed = {
        "aspect": options.fix_aspect,
        "principal_point": options.fix_principal_point,
        "k3": options.fix_k3,
    }
    return [name for name, on in fixed.items() if on]


def merge_intrinsics(
    current: Calibration | None,
    result: IntrinsicsResult,
    board: Board,
    serial: str | None,
    options: SolveOptions | None = None,
) -> Calibration:
    """``current`` (a new calibration when None) with the solved ``depth_camera``; the depth
    scale and depth offset in force are kept (the offset comes from the view step's boards:
    solve the view step again after new intrinsics, as the focal length sets the boards'
    size)."""
    camera = DepthCamera.from_intrinsics(result.intrinsics)
    camera.calibrated = provenance(
        serial,
        method="zhang",
        board=f"{board.cols}x{board.rows}@{board.square_mm}mm",
        rms_px=round(result.rms_px, 4),
        views_used=len(result.used),
        coverage=round(result.coverage, 3),
        per_image_px={v.name: round(v.error_px, 4) for v in result.used if v.error_px},
        fixed=fixed_names(options),
    )
    if current is None:
        return Calibration(format=CALIBRATION_FORMAT, depth_camera=camera)
    camera.depth_scale = current.depth_camera.depth_scale
    camera.depth_offset_m = current.depth_camera.depth_offset_m
    return current.model_copy(update={"depth_camera": camera})


def nominal_step_deg(session: Session) -> float:
    """The view step the session was captured with (the turn its table was told to make)."""
    step = session.calibration.view_step
    return step.angle_deg if step is not None else NOMINAL_STEP_DEG


def merge_view_step(
    base: Calibration, result: ViewStepResult, nominal_deg: float, serial: str | None
) -> Calibration:
    """``base`` with the solved ``view_step`` (its ``angle_deg`` the nominal turn)."""
    view_step = ViewStep(angle_deg=nominal_deg, matrix=result.T_view_k_view_k1)
    view_step.calibrated = provenance(
        serial,
        method="weighted SVD of checkerboard corners",
        rmse_mm=round(1000 * result.rmse_m, 3),
        solved_angle_deg=round(result.angle_deg, 4),
        points=result.points,
        pairs=result.pairs,
        **_offset_figures(result),
    )
    update: dict[str, object] = {"view_step": view_step}
    if result.depth_offset is not None:  # taken off every depth read from now on
        offset_m = round(result.depth_offset.offset_m, 4)
        update["depth_camera"] = base.depth_camera.model_copy(update={"depth_offset_m": offset_m})
    return base.model_copy(update=update)


def _offset_figures(result: ViewStepResult) -> dict[str, object]:
    """The depth offset the view step's boards showed, for its provenance."""
    found = result.depth_offset
    if found is None:
        return {}
    return {
        "depth_offset_mm": round(1000 * found.offset_m, 2),
        "depth_offset_spread_mm": round(1000 * found.spread_m, 2),
        "depth_offset_boards": found.boards,
    }


def stations_job(
    calibration: Calibration,
    session: Session,
    board: Board,
    reference: int,
    source: str = "the calibration",
) -> Callable[[], StationsResult]:
    """The station solve, ready to run: through ``calibration``'s view step, from the stations
    in force (else the session's) as the prior. Raises FieldappError naming ``source`` when the
    calibration has no view step yet."""
    if calibration.view_step is None:
        raise FieldappError(f"{source} has no view_step: calibrate the view step first")
    in_force_stations = calibration.stations or session.calibration.stations
    prior = in_force_stations.to_reference if in_force_stations else None
    return partial(
        calibrate_stations,
        _with_offset_of(calibration, session),
        board,
        calibration.view_step,
        reference,
        prior,
    )


def _with_offset_of(calibration: Calibration, session: Session) -> Session:
    """``session`` reading its depth with ``calibration``'s depth offset (the one its view step
    was solved with), whatever the session's own calibration says."""
    offset_m = calibration.depth_camera.depth_offset_m
    if offset_m == session.calibration.depth_camera.depth_offset_m:
        return session
    camera = session.calibration.depth_camera.model_copy(update={"depth_offset_m": offset_m})
    return replace(
        session, calibration=session.calibration.model_copy(update={"depth_camera": camera})
    )


def merge_stations(base: Calibration, result: StationsResult, serial: str | None) -> Calibration:
    """``base`` with the solved ``stations`` and its ``view_step`` refined with them."""
    base_poses = {
        s: StationPose(x=x, y=y, yaw_deg=yaw) for s, (x, y, yaw) in result.base_poses.items()
    }
    stations = Stations(
        reference=result.reference,
        to_reference=result.T_reference_station,
        base_poses=base_poses or None,
    )
    stations.calibrated = provenance(
        serial,
        method="checkerboards between stations: spanning tree, then joint refinement",
        pairs={f"{p.station_a}-{p.station_b}": round(1000 * p.fit.rmse_m, 3) for p in result.pairs},
        tree={str(s): parent for s, parent in sorted(result.tree.items())},
        joint_rmse_mm=round(1000 * result.bundle.rmse_m, 3),
        boards=result.bundle.boards,
        sightings=result.bundle.sightings,
    )
    update: dict[str, object] = {"stations": stations}
    if base.view_step is not None:
        view_step = base.view_step.model_copy(update={"matrix": result.T_view_k_view_k1})
        view_step.refined_with_stations = provenance(
            serial, solved_angle_deg=round(_turn_deg(result.T_view_k_view_k1), 4)
        )
        update["view_step"] = view_step
    return base.model_copy(update=update)


def _turn_deg(T_view_k_view_k1: NDArray[np.float64]) -> float:
    return rotation_angle_deg(T_view_k_view_k1[:3, :3])


def ground_job(
    session: Session, calibration: Calibration, settings: ReconstructionSettings | None = None
) -> Callable[[], GroundResult]:
    """The ground solve, ready to run, at the reference station of ``calibration`` (the
    session's depth read with its depth offset)."""
    return partial(calibrate_ground, _with_offset_of(calibration, session), calibration, settings)


def merge_ground(base: Calibration, result: GroundResult, serial: str | None) -> Calibration:
    """``base`` with the solved ``ground`` (reference frame into the field frame)."""
    ground = Ground(matrix=result.T_field_reference)
    ground.calibrated = provenance(
        serial,
        method="RANSAC plane of the reference station",
        camera_height_m=round(result.camera_height_m, 4),
        camera_pitch_deg=round(result.camera_pitch_deg, 3),
        station=result.station,
        inlier_fraction=round(result.inlier_fraction, 3),
        inlier_rms_mm=round(1000 * result.rms_m, 2),
        rms_mm=round(1000 * result.rms_m, 2),
    )
    return base.model_copy(update={"ground": ground})
