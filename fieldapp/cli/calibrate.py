"""``fieldapp calibrate intrinsics|...``: the calibration solvers on the command line."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from fieldapp.calib.verdict import Verdict


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "calibrate",
        help="calibrate the rig: intrinsics, view step, stations, ground",
        description="Calibrate the rig. Each solver prints its quality figures and says what "
        "to redo when they are poor; results are written into a calibration file, the "
        "previous file kept beside it.",
    )
    kinds = parser.add_subparsers(dest="kind", metavar="KIND", required=True)
    intrinsics = kinds.add_parser(
        "intrinsics",
        help="camera intrinsics (Zhang) from checkerboard images",
        description="Zhang calibration from checkerboard images (IR images for the Kinect's "
        "depth camera). Writes depth_camera into --out (other sections kept).",
    )
    intrinsics.add_argument(
        "images",
        nargs="+",
        type=Path,
        help="checkerboard images: files, folders of them, or quoted patterns ('ir/*.png')",
    )
    intrinsics.add_argument("--board", required=True, help="inner corners COLSxROWS, e.g. 9x6")
    intrinsics.add_argument("--square-mm", type=float, required=True, help="square size, mm")
    intrinsics.add_argument("--fix-aspect", action="store_true", help="force fx = fy")
    intrinsics.add_argument(
        "--fix-principal-point",
        nargs="?",
        const="centre",
        metavar="CX,CY",
        help="keep cx, cy fixed: at the image centre, or at CX,CY (pixels)",
    )
    intrinsics.add_argument(
        "--fix-k3", action="store_true", help="k3 = 0 (with few views k1, k2, k3 trade off)"
    )
    intrinsics.add_argument(
        "--max-view-error-px", type=float, default=1.5, help="reject views above this (1.5)"
    )
    intrinsics.add_argument("--serial", help="the camera's serial number, recorded")
    intrinsics.add_argument("--out", type=Path, required=True, help="calibration file to write")
    intrinsics.set_defaults(handler=run_intrinsics)

    views = kinds.add_parser(
        "views",
        help="the turntable's view-to-view transform from a board seen at views k and k+1",
        description="Solve view_step (view k+1 into view k) by weighted SVD on the board's "
        "corners, lifted to 3D with the registered depth, at consecutive views of a station.",
    )
    views.add_argument("session", type=Path, help="session whose views 0 and 1 see one board")
    _board_arguments(views)
    views.add_argument("--station", type=int, help="use this station only (default: all)")
    views.add_argument("--out", type=Path, required=True, help="calibration file to write")
    views.set_defaults(handler=run_views)

    stations = kinds.add_parser(
        "stations",
        help="station-to-station transforms from boards seen by neighbouring stations",
        description="Pairwise transforms through boards seen from two stations (captures "
        'tagged "target" in session.json), composed into stations.to_reference.',
    )
    stations.add_argument("session", type=Path, help="session with board-tagged captures")
    _board_arguments(stations)
    stations.add_argument("--reference", type=int, default=5, help="reference station (5)")
    stations.add_argument(
        "--calibration", type=Path, required=True, help="calibration with the view_step to use"
    )
    stations.add_argument("--out", type=Path, required=True, help="calibration file to write")
    stations.set_defaults(handler=run_stations)

    ground = kinds.add_parser(
        "ground",
        help="the ground plane of the reference station (ground.matrix)",
        description="Fit the ground plane (RANSAC) of the reference station, all its views "
        "joined, and write ground.matrix: the reference frame into the field frame (z up, 0 "
        "on the ground, origin below the camera, x along its forward direction).",
    )
    ground.add_argument("session", type=Path, help="session with the reference station's views")
    ground.add_argument(
        "--calibration", type=Path, required=True, help="calibration with view_step and stations"
    )
    ground.add_argument("--serial", help="the rig's serial number, recorded")
    ground.add_argument("--out", type=Path, required=True, help="calibration file to write")
    ground.set_defaults(handler=run_ground)


def _board_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--board", required=True, help="inner corners COLSxROWS, e.g. 9x6")
    parser.add_argument("--square-mm", type=float, required=True, help="square size, mm")
    parser.add_argument("--serial", help="the rig's serial number, recorded")


def run_intrinsics(args: argparse.Namespace) -> int:
    from fieldapp.calib import service
    from fieldapp.calib.board import Board
    from fieldapp.calib.image_files import expand_image_paths, read_images
    from fieldapp.calib.intrinsics import calibrate_intrinsics
    from fieldapp.calib.verdict import intrinsics_verdict

    board = Board.parse(args.board, args.square_mm)
    images, skipped = read_images(expand_image_paths(args.images))
    for line in skipped:
        print(f"warning: {line}")
    options = _solve_options(args)
    result = calibrate_intrinsics(
        images, board, max_view_error_px=args.max_view_error_px, options=options
    )
    calibration = service.merge_intrinsics(
        service.in_force(args.out), result, board, args.serial, options
    )
    previous = service.save(args.out, calibration)
    k = result.intrinsics
    print(f"fx {k.fx:.4f}  fy {k.fy:.4f}  cx {k.cx:.4f}  cy {k.cy:.4f}")
    print("distortion (k1 k2 p1 p2 k3): " + " ".join(f"{d:.6f}" for d in k.distortion))
    print(f"RMS reprojection error {result.rms_px:.4f} px over {len(result.used)} views")
    for view in result.views:
        if view.rejected is None:
            print(f"  {view.name}: {view.error_px:.4f} px")
        else:
            print(f"  {view.name}: REJECTED: {view.rejected}")
    print(f"corner coverage {100 * result.coverage:.0f} % of the image")
    return _finish(result.warnings, intrinsics_verdict(result), args.out, previous)


def _solve_options(args: argparse.Namespace) -> Any:
    from fieldapp.calib.intrinsics import SolveOptions
    from fieldapp.errors import FieldappError

    point = None
    if args.fix_principal_point not in (None, "centre"):
        try:
            cx, cy = (float(v) for v in args.fix_principal_point.split(","))
        except ValueError:
            raise FieldappError(
                f"--fix-principal-point {args.fix_principal_point!r}: expected CX,CY in pixels"
            ) from None
        point = (cx, cy)
    return SolveOptions(
        fix_aspect=args.fix_aspect,
        fix_principal_point=args.fix_principal_point is not None,
        principal_point=point,
        fix_k3=args.fix_k3,
    )


def _load(path: Path) -> Any:
    from fieldapp.errors import FieldappError, FormatError
    from fieldapp.io.session import load_session

    try:
        return load_session(path)
    except FormatError as error:
        raise FieldappError(f"{path} is not a usable session:\n{error}") from None


def run_views(args: argparse.Namespace) -> int:
    from fieldapp.calib import service
    from fieldapp.calib.board import Board
    from fieldapp.calib.verdict import views_verdict
    from fieldapp.calib.views import calibrate_view_step

    session = _load(args.session)
    board = Board.parse(args.board, args.square_mm)
    result = calibrate_view_step(session, board, args.station)
    nominal_deg = service.nominal_step_deg(session)
    base = service.in_force(args.out) or session.calibration
    calibration = service.merge_view_step(base, result, nominal_deg, args.serial)
    previous = service.save(args.out, calibration)
    print(
        f"view_step: turn {result.angle_deg:.4f} degrees, translation "
        + " ".join(f"{x:+.4f}" for x in result.T_view_k_view_k1[:3, 3])
        + " m"
    )
    print(f"feature point RMSE {1000 * result.rmse_m:.2f} mm over {result.points} corners")
    if result.depth_offset is not None:
        print(result.depth_offset.text())
    for pair in result.pairs:
        print(f"  {pair}")
    return _finish(result.warnings, views_verdict(result, nominal_deg), args.out, previous)


def run_stations(args: argparse.Namespace) -> int:
    from fieldapp.calib import service
    from fieldapp.calib.board import Board
    from fieldapp.calib.verdict import stations_verdict
    from fieldapp.io.calibration import load_calibration

    session = _load(args.session)
    calibration = load_calibration(args.calibration)
    board = Board.parse(args.board, args.square_mm)
    job = service.stations_job(calibration, session, board, args.reference, str(args.calibration))
    result = job()
    previous = service.save(args.out, service.merge_stations(calibration, result, args.serial))
    for pair in result.pairs:
        print(
            f"stations {pair.station_a}-{pair.station_b} via {', '.join(pair.boards)}: "
            f"RMSE {1000 * pair.fit.rmse_m:.2f} mm"
        )
    for station, parent in sorted(result.tree.items()):
        t = result.T_reference_station[station][:3, 3]
        print(f"station {station} (via {parent}): " + " ".join(f"{x:+.4f}" for x in t) + " m")
    print(
        f"joint refinement over {result.bundle.sightings} sightings of "
        f"{result.bundle.boards} boards: RMSE {1000 * result.bundle.rmse_m:.2f} mm "
        "(view_step refined too)"
    )
    return _finish(result.warnings, stations_verdict(result), args.out, previous)


def run_ground(args: argparse.Namespace) -> int:
    from fieldapp.calib import service
    from fieldapp.calib.verdict import ground_verdict
    from fieldapp.io.calibration import load_calibration
    from fieldapp.settings import load_settings

    session = _load(args.session)
    calibration = load_calibration(args.calibration)
    settings = load_settings().reconstruction
    result = service.ground_job(session, calibration, settings)()
    previous = service.save(args.out, service.merge_ground(calibration, result, args.serial))
    print(
        f"camera {result.camera_height_m:.3f} m above the ground, pitched "
        f"{result.camera_pitch_deg:.2f} degrees down"
    )
    distance_cm = 100 * settings.ground.ransac_distance_m
    print(
        f"ground plane from station {result.station}: {100 * result.inlier_fraction:.0f} % of "
        f"{result.points} points within {distance_cm:g} cm, RMS {1000 * result.rms_m:.1f} mm"
    )
    if result.change_from_previous is not None:
        moved_m, turned_deg = result.change_from_previous
        print(f"change from the ground in force: {100 * moved_m:.1f} cm, {turned_deg:.2f} degrees")
    return _finish(result.warnings, ground_verdict(result), args.out, previous)


def _finish(warnings: list[str], verdict: Verdict, out: Path, previous: Path | None) -> int:
    """Every solver's last lines: its warnings, the verdict, where it wrote, what it kept."""
    for warning in warnings:
        print(f"warning: {warning}")
    print(f"quality: {verdict.text()}")
    print(f"written to {out}" + (f" (previous kept as {previous})" if previous else ""))
    return 0
