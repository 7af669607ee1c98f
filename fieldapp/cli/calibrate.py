"""``fieldapp calibrate intrinsics|...``: the calibration solvers on the command line."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "calibrate",
        help="calibrate the rig (intrinsics, ...)",
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
    intrinsics.add_argument("images", nargs="+", type=Path, help="checkerboard images")
    intrinsics.add_argument("--board", required=True, help="inner corners COLSxROWS, e.g. 9x6")
    intrinsics.add_argument("--square-mm", type=float, required=True, help="square size, mm")
    intrinsics.add_argument("--fix-aspect", action="store_true", help="force fx = fy")
    intrinsics.add_argument(
        "--max-view-error-px", type=float, default=1.5, help="reject views above this (1.5)"
    )
    intrinsics.add_argument("--serial", help="the camera's serial number, recorded")
    intrinsics.add_argument("--out", type=Path, required=True, help="calibration file to write")
    intrinsics.set_defaults(handler=run_intrinsics)


def run_intrinsics(args: argparse.Namespace) -> int:
    from fieldapp.calib.board import Board
    from fieldapp.calib.intrinsics import calibrate_intrinsics, read_calibration_image
    from fieldapp.calib.store import provenance, save_keeping_previous, with_depth_camera
    from fieldapp.io.calibration import DepthCamera

    board = Board.parse(args.board, args.square_mm)
    images = [(str(path), read_calibration_image(path)) for path in args.images]
    result = calibrate_intrinsics(images, board, args.fix_aspect, args.max_view_error_px)
    k = result.intrinsics
    camera = DepthCamera.from_intrinsics(k)
    camera.calibrated = provenance(  # type: ignore[attr-defined]
        args.serial,
        method="zhang",
        board=f"{board.cols}x{board.rows}@{board.square_mm}mm",
        rms_px=round(result.rms_px, 4),
        views_used=len(result.used),
        coverage=round(result.coverage, 3),
        per_image_px={v.name: round(v.error_px, 4) for v in result.used if v.error_px},
    )
    previous = save_keeping_previous(args.out, with_depth_camera(args.out, camera))
    print(f"fx {k.fx:.4f}  fy {k.fy:.4f}  cx {k.cx:.4f}  cy {k.cy:.4f}")
    print("distortion (k1 k2 p1 p2 k3): " + " ".join(f"{d:.6f}" for d in k.distortion))
    print(f"RMS reprojection error {result.rms_px:.4f} px over {len(result.used)} views")
    for view in result.views:
        if view.rejected is None:
            print(f"  {view.name}: {view.error_px:.4f} px")
        else:
            print(f"  {view.name}: REJECTED: {view.rejected}")
    print(f"corner coverage {100 * result.coverage:.0f} % of the image")
    for warning in result.warnings:
        print(f"warning: {warning}")
    print(f"written to {args.out}" + (f" (previous kept as {previous})" if previous else ""))
    return 0
