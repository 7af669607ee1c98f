"""``fieldapp import folder|bag|cloud``: other tools' data into fieldapp (``docs/DATA.md``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from fieldapp.errors import FieldappError


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "import",
        help="bring your own data in: depth-image folders, RealSense recordings, point clouds",
        description="Import depth images or a RealSense recording into a session folder (then "
        "`fieldapp verify` and `fieldapp reconstruct` it), or take a point cloud straight to "
        "the plant and trait steps. Everything that cannot be used is named, one line each.",
    )
    kinds = parser.add_subparsers(dest="kind", metavar="KIND", required=True)
    folder = kinds.add_parser(
        "folder",
        help="a folder of depth images (with colour and IR where present) into a session",
        description="Depth images (16-bit PNG/TIFF in 1/--depth-scale m, or float metres in "
        ".npy/TIFF) with colour and IR where present. File names give each file's kind (depth, "
        "color/rgb, ir), station (s2), view (v3) or angle (045deg); see docs/DATA.md.",
    )
    folder.add_argument("folder", type=Path, help="the folder of images (searched recursively)")
    _camera_arguments(folder)
    folder.add_argument(
        "--depth-scale", type=float, default=1000.0, help="depth units per metre (1000: mm)"
    )
    folder.add_argument(
        "--step-deg", type=float, help="the table's turn between views (else from the names)"
    )
    _common(folder)
    folder.set_defaults(handler=run_folder)

    bag = kinds.add_parser(
        "bag",
        help="a RealSense recording (.bag) into a session, through the SDK's playback",
        description="Every --every-th frame set of the recording becomes the next view of "
        "station 1, depth aligned to colour when the recording has colour (depth-only "
        "otherwise). Intrinsics come from the recording.",
    )
    bag.add_argument("recording", type=Path, help="the recording (.bag; .db3 from SDK 2.56 on)")
    bag.add_argument("--every", type=int, default=1, help="keep one frame set in N (1)")
    bag.add_argument("--max-views", type=int, help="stop after this many views")
    bag.add_argument("--step-deg", type=float, default=45.0, help="turn between views (45)")
    _common(bag)
    bag.set_defaults(handler=run_bag)

    cloud = kinds.add_parser(
        "cloud",
        help="a point cloud (PLY, PCD, XYZ, LAS/LAZ) straight to plants and traits",
        description="Read a joined point cloud of a plot or a plant, level it on its ground "
        "plane, separate plants from soil, cluster and measure them; writes plants.csv, "
        "cloud.ply, plants/ and report.json into --out, as `fieldapp reconstruct` does.",
    )
    cloud.add_argument("cloud", type=Path, help="the point cloud file")
    cloud.add_argument("--out", type=Path, required=True, help="the results folder to write")
    cloud.add_argument("--units", default="m", help="the file's length unit: m (default), cm, mm")
    cloud.add_argument("--up", default="z", help="the file's up axis: z (default), y, -y, x...")
    cloud.add_argument(
        "--min-height-m", type=float, default=0.02, help="plant points are this far above ground"
    )
    cloud.add_argument("--settings", type=Path, help="settings YAML (default: the user's)")
    cloud.set_defaults(handler=run_cloud)


def _camera_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--intrinsics", help="depth camera fx,fy,cx,cy[,k1,k2,p1,p2,k3] (px)")
    parser.add_argument(
        "--calibration",
        type=Path,
        help="fieldapp calibration.json (its view step and stations are used too) or OpenCV .yml",
    )


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--axis-distance-m",
        type=float,
        default=0.0,
        help="0: the camera turns on the table (default); D: the camera is fixed and the "
        "table (plant) turns D metres in front of it",
    )
    parser.add_argument("--id", help="the session id (default: the source's name)")
    parser.add_argument("--out", type=Path, required=True, help="the new session folder")


def _check_out(out: Path) -> None:
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise FieldappError(f"--out: {out} exists and is not an empty folder")


def run_folder(args: argparse.Namespace) -> int:
    from fieldapp.imports.folder import FolderOptions, import_folder

    _check_out(args.out)
    options = FolderOptions(
        intrinsics=args.intrinsics,
        calibration=args.calibration,
        depth_scale=_positive("--depth-scale", args.depth_scale),
        step_deg=args.step_deg,
        axis_distance_m=args.axis_distance_m,
        session_id=args.id,
    )
    return _finish(import_folder(args.folder, args.out, options))


def run_bag(args: argparse.Namespace) -> int:
    from fieldapp.imports.bag import BagOptions, import_bag

    _check_out(args.out)
    options = BagOptions(
        every=args.every,
        step_deg=args.step_deg,
        axis_distance_m=args.axis_distance_m,
        max_views=args.max_views,
        session_id=args.id,
    )
    return _finish(import_bag(args.recording, args.out, options))


def run_cloud(args: argparse.Namespace) -> int:
    from fieldapp.imports.cloud_traits import cloud_traits, write_cloud_results
    from fieldapp.imports.clouds import read_cloud
    from fieldapp.settings import load_settings

    settings = load_settings(args.settings).reconstruction
    loaded = read_cloud(args.cloud, args.units, args.up)
    result = cloud_traits(loaded, settings, _positive("--min-height-m", args.min_height_m))
    write_cloud_results(args.out, args.cloud, result)
    print(f"{len(loaded.cloud)} points; {result.ground}; plants: {result.separation}")
    for warning in result.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    print(f"{len(result.plants)} plants -> {args.out / 'plants.csv'}")
    return 0


def _positive(name: str, value: float) -> float:
    if not value > 0:
        raise FieldappError(f"{name} {value:g}: must be positive")
    return value


def _finish(result: Any) -> int:
    """Every line the import could not use, then the session checked as `verify` does."""
    from fieldapp.verify import verify_session

    for line in result.lines:
        print(line)
    report = verify_session(result.out)
    depth_only = f", {result.depth_only} depth-only" if result.depth_only else ""
    print(f"{result.out}: {result.captures} captures imported{depth_only}")
    for line in report.summary_lines():
        print(line)
    for problem in report.problems:
        print(f"problem: {problem}", file=sys.stderr)
    return 0 if report.usable else 1
