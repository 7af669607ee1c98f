"""``fieldapp simulate --out DIR``: write a simulated capture session with its ground truth.

The session follows the spec (``shared/spec/session-format.md``): captures of the chosen
stations and views, ``calibration.json`` with the *nominal* rig transforms (what a
pre-calibration would give), and ``truth.json`` with what was really there (see
:mod:`devices.sim.truth`). ``--scene checkerboard`` adds the calibration boards, the captures
tagged with the board they see, and IR images of a board under ``DIR/intrinsics/``.
"""

from __future__ import annotations

import argparse
import logging
from collections import deque
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fieldapp.errors import FieldappError

if TYPE_CHECKING:
    from devices.camera.frames import Intrinsics
    from devices.sim.rig import RigGeometry, StopErrors
    from devices.sim.scene import PlotLayout
    from devices.sim.survey import SimCapture
    from devices.sim.world import SimWorld
    from fieldapp.io.calibration import Calibration
    from fieldapp.io.writer import SessionWriter

log = logging.getLogger(__name__)

SCENES = ("plot", "spheres", "soil", "checkerboard", "turntable")
MAX_ARRIVAL_M = 0.10
MAX_ARRIVAL_DEG = 5.0
MAX_LOCALISATION_M = 0.25
MAX_LOCALISATION_DEG = 10.0
MAX_DEPTH_OFFSET_M = 0.05
MAX_VEIL_PX = 6
_ON_THE_RIG = ("plot", "spheres", "soil", "checkerboard")
SCENE_OPTIONS: dict[str, tuple[str, ...]] = {
    "grid": _ON_THE_RIG,
    "arrival_error": _ON_THE_RIG,
    "localisation_error": _ON_THE_RIG,
    "table_error": _ON_THE_RIG,
    "color_shift": _ON_THE_RIG,
    "depth_offset": _ON_THE_RIG,
    "lens_distortion": _ON_THE_RIG,
    "sunlight": _ON_THE_RIG,
    "color_noise": (*_ON_THE_RIG, "turntable"),
    "veil": _ON_THE_RIG,
    "camera": _ON_THE_RIG,
    "station_spacing": ("plot", "spheres", "soil"),
    "base_tilt": ("plot", "spheres", "soil"),
    "stations": _ON_THE_RIG,
    "stage": ("plot",),
    "plant_model": ("plot",),
    "lean": ("plot",),
    "leaf_width": ("plot",),
    "grounded_leaves": ("plot",),
    "late_plants": ("plot",),
    "clods": ("plot",),
    "clod_size": ("plot",),
    "dry_tips": ("plot",),
    "plants": ("spheres",),
    "intrinsics_images": ("checkerboard",),
}
"""The scenes each option acts on (argparse ``dest``); given to another scene, it is refused."""


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "simulate",
        help="write a simulated capture session (and its ground truth)",
        description="Simulate the rig in the default world (a plot of maize seedlings on uneven "
        "soil) and write a capture session, its nominal calibration and truth.json.",
    )
    parser.add_argument("--out", required=True, type=Path, help="the new session folder")
    parser.add_argument(
        "--scene",
        default="plot",
        help="plot (default), spheres, soil (bare), checkerboard or turntable (a plant turning "
        "on a table before a fixed camera, in a room; one station)",
    )
    parser.add_argument(
        "--grid",
        default=None,
        help="stations per side of the plot, 2..9 (default 3; plants spread over it)",
    )
    parser.add_argument(
        "--arrival-error",
        default=None,
        metavar="M,DEG",
        help="standard deviation of the base's true arrival from the nominal station pose: "
        "metres per axis and degrees of yaw, up to 0.1,5 (default about 0.025,1)",
    )
    parser.add_argument(
        "--localisation-error",
        default=None,
        metavar="M,DEG",
        help="standard deviation of the base's error in its own estimate of where it stopped, "
        "the part of its arrival error it does not report (a base localising poorly): metres "
        "per axis and degrees of yaw, up to 0.25,10 (default: the share of the arrival error, "
        "about 0.015,0.6)",
    )
    parser.add_argument(
        "--table-error",
        default=None,
        metavar="DEG",
        help="the table stops up to DEG degrees off each view's angle (0..3) and reports the "
        "angle it reached, as a table with an encoder does (default: a few hundredths, "
        "reporting its target as Grbl does)",
    )
    parser.add_argument(
        "--color-shift",
        default=None,
        metavar="DX,DY",
        help="colour images registered DX, DY pixels off the depth (integers, up to 3 a side), "
        "as a Kinect v2's registration can leave them (default: exact)",
    )
    parser.add_argument(
        "--color-holes",
        action="store_true",
        help="colour as libfreenect2 registers a Kinect v2's: black (no colour) where the "
        "colour camera, 5.2 cm beside the depth camera and with a less high field of view, "
        "does not see the depth pixel (rows at the top and bottom, a band beside every near "
        "edge)",
    )
    parser.add_argument(
        "--depth-offset",
        default=None,
        metavar="M",
        help="a static offset added to every depth the sensor measures, metres (-0.05..0.05), "
        "as a Kinect v2 unit can have after calibration (default: none)",
    )
    parser.add_argument(
        "--sunlight",
        default=None,
        metavar="S",
        help="the sun's infrared on the depth camera, a share of a clear midday sun (0..1): "
        "depth noise rising with the ambient light over the returned light, and no depth where "
        "the return drowns in it (default: none, as under cloud)",
    )
    parser.add_argument(
        "--color-noise",
        default=None,
        metavar="L",
        help="each colour channel's own noise, standard deviation in 8-bit levels (0..10): dark "
        "pixels (shade, moist soil, clods) change hue, as a colour camera's do (default: none, "
        "brightness noise only)",
    )
    parser.add_argument(
        "--veil",
        default=None,
        metavar="PX",
        help="flying pixels as a veil PX pixels deep (1..6) beside every depth edge, stepping "
        "evenly from the near surface to the far one, as a time-of-flight camera's optics and "
        "smoothing spread an edge (default: none, single flying pixels only)",
    )
    parser.add_argument(
        "--clods",
        default=None,
        metavar="N",
        help="plot scene: clods and stones on the soil, N per square metre (0..60; a tilled "
        "seedbed has 10-40): 2.4-8 cm across, standing 1-4.5 cm out of the soil, darker than "
        "it, none within 7 cm of a stem (default: none)",
    )
    parser.add_argument(
        "--clod-size",
        default=None,
        metavar="CM",
        help="with --clods: the largest clods this many centimetres across (8..16; default 8): "
        "a coarse seedbed's clods, whose tops low leaves rest on",
    )
    parser.add_argument(
        "--dry-tips",
        default=None,
        metavar="CM",
        help="the last this many centimetres of every leaf tan, the soil's colour (1..15; "
        "default: none): "
        "tips dried by drought or frost, or whose colour the soil's mixes with at 2 m; the "
        "plants' shapes, and their truth, unchanged",
    )
    parser.add_argument(
        "--camera",
        default=None,
        metavar="M,DEG",
        help="the rig's camera: height of its optical centre above the ground in metres and "
        "pitch below the horizontal in degrees (default 1.3,45, the paper's rig)",
    )
    parser.add_argument(
        "--station-spacing",
        default=None,
        metavar="M",
        help="the stations this far apart in metres (0.6..2.4; default 1.6, the paper's plan); "
        "the plants stay where the default plan has them (4 x 4 at 0.8 m on a 3 x 3 plan), "
        "so with stations nearer together the outer plants stand farther beyond the outer "
        "stations",
    )
    parser.add_argument(
        "--base-tilt",
        default=None,
        metavar="DEG",
        help="rough ground under the wheels: at each stop every wheel on a clod or in a rut, "
        "tilting the base up to DEG degrees about each axis beyond the soil's own slope "
        "(0..10; default: the soil's slope alone, a degree or less)",
    )
    parser.add_argument("--seed", default="0", help="world seed (same seed, same plants)")
    parser.add_argument("--day", default="0", help="days since the first scan (plants grow)")
    parser.add_argument(
        "--stage",
        default=None,
        help="plot growth stage: seedling (default) or touching (55-90 cm, 5-8 leaves, "
        "canopies reaching across the 80 cm spacing)",
    )
    parser.add_argument(
        "--plant-model",
        default=None,
        help="plot scene's plants: distichous (default: leaves at 180 degrees, set along the "
        "rows when touching) or irregular (a second model: phyllotaxy off 180 degrees, plants "
        "turned at random, twisted wavy leaves, erect to drooping)",
    )
    parser.add_argument(
        "--lean",
        default=None,
        metavar="DEG",
        help="plot scene: the largest lean of a plant's stem in degrees, 0..30 (default: the "
        "plant model's own, 5 or 6); each plant leans its own share of it, its own way",
    )
    parser.add_argument(
        "--leaf-width",
        default=None,
        metavar="F",
        help="plot scene: every leaf blade F times as wide as the plant model draws it, "
        "0.3..1.5 (default 1: seedling blades 5-11 cm wide in the first model, about 4.5 in "
        "the second; a maize seedling's are 1.5-4 cm, about 0.35)",
    )
    parser.add_argument(
        "--grounded-leaves",
        default=None,
        metavar="S",
        help="plot scene: each leaf of a plant's lower half arches over and comes down to the "
        "soil with this chance, 0..1, its tip 8-55 cm from the stem, as older plants' lower "
        "leaves do (default 0)",
    )
    parser.add_argument(
        "--late-plants",
        default=None,
        metavar="F",
        help="plot scene at the touching stage: each plant came up late with this chance, "
        "0..1, and is a seedling among grown plants whose leaves may reach it, as uneven "
        "emergence leaves a field (default 0)",
    )
    parser.add_argument(
        "--stations", default=None, help="stations to visit, e.g. 4,5 or 1-9 (default: all)"
    )
    parser.add_argument("--views", default="0-7", help="views per station, e.g. 0,1 or 0-7")
    parser.add_argument("--plants", action="store_true", help="spheres scene: add the plants")
    parser.add_argument(
        "--lens-distortion",
        action="store_true",
        help="depth and colour images as a Kinect v2 gives them before undistortion: its "
        "lens's radial distortion (k1 0.09, k2 -0.27, k3 0.09) in the images, and in the "
        "calibration as a recorder of raw frames writes it",
    )
    parser.add_argument(
        "--depth-only",
        action="store_true",
        help="write depth-only captures (no colour image), as a sensor without colour records",
    )
    parser.add_argument(
        "--intrinsics-images",
        default=None,
        help="checkerboard scene: IR board images (0-100, default 20)",
    )
    parser.set_defaults(handler=run)


def parse_int(name: str, text: str, low: int, high: int) -> int:
    """``text`` as an integer in [low, high], or a :class:`FieldappError` naming the option."""
    try:
        value = int(text)
    except ValueError:
        raise FieldappError(f"--{name}: {text!r} is not a whole number") from None
    if not low <= value <= high:
        raise FieldappError(f"--{name}: {value} is outside {low}..{high}")
    return value


def parse_list(name: str, text: str, low: int, high: int) -> list[int]:
    """``"1,3-5"`` -> ``[1, 3, 4, 5]``, every number in [low, high]; sorted, unique."""
    values: set[int] = set()
    for part in text.split(","):
        first, _, last = part.strip().partition("-")
        start = parse_int(name, first, low, high)
        values.update(range(start, parse_int(name, last, low, high) + 1) if last else [start])
    if not values:
        raise FieldappError(f"--{name}: {text!r} selects nothing")
    return sorted(values)


CAMERA_HEIGHTS_M = (0.6, 2.5)
STATION_SPACINGS_M = (0.6, 2.4)
MAX_BASE_TILT_DEG = 10.0
CAMERA_PITCHES_DEG = (20.0, 80.0)


def parse_camera(text: str | None) -> dict[str, float]:
    """``"1.6,35"`` -> the rig's camera height (m) and pitch (degrees down) as
    :class:`~devices.sim.rig.RigGeometry` fields, each within the option's range; ``None``:
    none (the paper's rig)."""
    if text is None:
        return {}
    try:
        height_m, pitch_deg = (float(p) for p in text.split(","))
    except ValueError:
        raise FieldappError(f"--camera: {text!r} is not two numbers M,DEG (e.g. 1.6,35)") from None
    (low_m, high_m), (low_deg, high_deg) = CAMERA_HEIGHTS_M, CAMERA_PITCHES_DEG
    if not (low_m <= height_m <= high_m and low_deg <= pitch_deg <= high_deg):
        raise FieldappError(
            f"--camera: {text!r} is outside {low_m:g}..{high_m:g} m, {low_deg:g}..{high_deg:g} deg"
        )
    return {"camera_height_m": height_m, "pitch_deg": pitch_deg}


def parse_arrival(
    text: str | None,
    option: str = "--arrival-error",
    limits: tuple[float, float] = (MAX_ARRIVAL_M, MAX_ARRIVAL_DEG),
) -> tuple[float, float] | None:
    """``"0.03,1.5"`` -> (0.03 m, 1.5 deg), each within ``limits``; ``None`` stays."""
    if text is None:
        return None
    parts = text.split(",")
    try:
        sigma_m, sigma_deg = (float(p) for p in parts)
    except ValueError:
        raise FieldappError(
            f"{option}: {text!r} is not two numbers M,DEG (e.g. 0.03,1.5)"
        ) from None
    if not (0.0 <= sigma_m <= limits[0] and 0.0 <= sigma_deg <= limits[1]):
        raise FieldappError(
            f"{option}: {text!r} is outside 0..{limits[0]:g} m, 0..{limits[1]:g} deg"
        )
    return sigma_m, sigma_deg


def parse_color_shift(text: str | None) -> tuple[int, int] | None:
    """``"1,-2"`` -> (1, -2) pixels, each within
    :data:`~devices.sim.sensor.MAX_COLOR_SHIFT_PX`; ``None`` stays (exact registration)."""
    if text is None:
        return None
    from devices.sim.sensor import MAX_COLOR_SHIFT_PX

    try:
        dx, dy = (int(part) for part in text.split(","))
    except ValueError:
        raise FieldappError(
            f"--color-shift: {text!r} is not two whole numbers of pixels DX,DY (e.g. 1,-1)"
        ) from None
    if max(abs(dx), abs(dy)) > MAX_COLOR_SHIFT_PX:
        raise FieldappError(
            f"--color-shift: {text!r} is outside -{MAX_COLOR_SHIFT_PX}..{MAX_COLOR_SHIFT_PX} "
            "pixels a side"
        )
    return dx, dy


def parse_degrees(option: str, text: str | None, limit: float) -> float | None:
    """``"15"`` -> 15.0 degrees for ``option`` (``--lean``, ``--table-error``), within
    0..``limit``; ``None`` stays (the simulator's own)."""
    return parse_number(option, text, 0.0, limit, "degrees")


def parse_number(option: str, text: str | None, low: float, high: float, unit: str) -> float | None:
    """``option``'s value as a number of ``unit`` within ``low``..``high``; ``None`` stays."""
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        raise FieldappError(f"{option}: {text!r} is not a number of {unit}") from None
    if not low <= value <= high:
        raise FieldappError(f"{option}: {value:g} is outside {low:g}..{high:g} {unit}")
    return value


def check_scene_options(args: argparse.Namespace) -> None:
    """Refuse an option the chosen scene would ignore: a session made without what was asked
    for is worse than an error naming the option."""
    if args.scene not in SCENES:
        raise FieldappError(f"--scene: {args.scene!r} is not one of {', '.join(SCENES)}")
    for dest, scenes in SCENE_OPTIONS.items():
        if getattr(args, dest) not in (None, False) and args.scene not in scenes:
            option = "--" + dest.replace("_", "-")
            takers = ", ".join(scenes[:-1]) + " and " * (len(scenes) > 1) + scenes[-1]
            raise FieldappError(
                f"{option}: the {args.scene} scene does not take it (only {takers})"
            )


def run(args: argparse.Namespace) -> int:
    from devices.sim.rig import MAX_GRID, MAX_TABLE_ERROR_DEG, RigGeometry, StopErrors

    check_scene_options(args)
    args.grid = args.grid or "3"
    args.stage = args.stage or "seedling"
    args.plant_model = args.plant_model or "distichous"
    args.intrinsics_images = args.intrinsics_images or "20"
    from devices.sim.plants import LEAF_WIDTH_RANGE, MAX_LEAN_DEG, PLANT_MODELS, STAGES

    seed = parse_int("seed", args.seed, 0, 2**31 - 1)
    day = parse_int("day", args.day, 0, 120)
    if args.stage not in STAGES:
        raise FieldappError(f"--stage: {args.stage!r} is not one of {', '.join(STAGES)}")
    if args.plant_model not in PLANT_MODELS:
        raise FieldappError(
            f"--plant-model: {args.plant_model!r} is not one of {', '.join(PLANT_MODELS)}"
        )
    grid, camera = parse_int("grid", args.grid, 2, MAX_GRID), parse_camera(args.camera)
    rig = RigGeometry(grid=grid)
    spacing = parse_number("--station-spacing", args.station_spacing, *STATION_SPACINGS_M, "metres")
    if spacing is not None:
        rig = replace(rig, station_spacing_m=spacing)
    tilt = parse_number("--base-tilt", args.base_tilt, 0.0, MAX_BASE_TILT_DEG, "degrees")
    if tilt is not None:
        rig = replace(rig, max_tilt_deg=tilt, tilt_seed=seed)
    if camera:
        rig = replace(rig, camera_height_m=camera["camera_height_m"], pitch_deg=camera["pitch_deg"])
    last = rig.grid**2
    stations = parse_list("stations", args.stations or f"1-{last}", 1, last)
    views = parse_list("views", args.views, 0, rig.views - 1)
    shots = parse_int("intrinsics-images", args.intrinsics_images, 0, 100)
    arrival = parse_arrival(args.arrival_error)
    localisation = parse_arrival(
        args.localisation_error,
        "--localisation-error",
        (MAX_LOCALISATION_M, MAX_LOCALISATION_DEG),
    )
    lean = parse_degrees("--lean", args.lean, MAX_LEAN_DEG)
    leaf_width = parse_number("--leaf-width", args.leaf_width, *LEAF_WIDTH_RANGE, "times the width")
    grounded = parse_number("--grounded-leaves", args.grounded_leaves, 0.0, 1.0, "(a chance)")
    late = parse_number("--late-plants", args.late_plants, 0.0, 1.0, "(a chance)")
    if late is not None and args.stage != "touching":
        raise FieldappError("--late-plants: only at --stage touching (late plants are seedlings)")
    table_error = parse_degrees("--table-error", args.table_error, MAX_TABLE_ERROR_DEG)
    color_shift = parse_color_shift(args.color_shift)
    depth_offset = parse_number(
        "--depth-offset", args.depth_offset, -MAX_DEPTH_OFFSET_M, MAX_DEPTH_OFFSET_M, "metres"
    )
    sunlight = parse_number("--sunlight", args.sunlight, 0.0, 1.0, "of a clear midday sun")
    color_noise = parse_number("--color-noise", args.color_noise, 0.0, 10.0, "levels")
    veil = None if args.veil is None else parse_int("veil", args.veil, 1, MAX_VEIL_PX)
    clods = parse_number("--clods", args.clods, 0.0, 60.0, "per square metre")
    clod_size = parse_number("--clod-size", args.clod_size, 8.0, 16.0, "centimetres")
    dry_tips = parse_number("--dry-tips", args.dry_tips, 1.0, 15.0, "centimetres")
    if clod_size is not None and not clods:
        raise FieldappError("--clod-size: give --clods too (how many clods a square metre)")
    errors = StopErrors.arrival(*arrival) if arrival else StopErrors()
    if localisation is not None:
        errors = replace(errors, locate_m=localisation[0], locate_deg=localisation[1])
    if table_error is not None:
        errors = StopErrors.table(table_error, errors)
    if args.scene == "checkerboard" and rig.grid != 3:
        raise FieldappError("--grid: the checkerboard scene is laid out for the 3 x 3 plan")
    if args.out.exists() and not args.out.is_dir():
        raise FieldappError(f"--out: {args.out} exists and is not a folder")
    try:
        if args.scene == "turntable":
            count = _write_turntable(
                args.out, seed, day, views, args.depth_only, args.color_holes, color_noise
            )
        else:
            world = build_world(
                args.scene,
                seed,
                day,
                rig,
                args.plants,
                args.stage,
                args.plant_model,
                lean,
                depth_offset,
                sunlight,
                leaf_width,
                args.lens_distortion,
                color_noise=color_noise,
                veil_px=veil,
                clods_per_m2=clods,
                clod_size_m=None if clod_size is None else clod_size / 100.0,
                dry_tips_m=None if dry_tips is None else dry_tips / 100.0,
                grounded_leaves=grounded,
                late_plants=late,
            )
            about: dict[str, Any] = {"scene": args.scene, "seed": seed, "day": day}
            about |= {"stage": args.stage, "grid": rig.grid}
            if args.plant_model != "distichous":  # absent: the first model (sessions unchanged)
                about["plant_model"] = args.plant_model
            if lean is not None:  # absent: the model's own leans (sessions unchanged)
                about["max_lean_deg"] = lean
            if leaf_width is not None:  # absent: the model's own blades (sessions unchanged)
                about["leaf_width"] = leaf_width
            if arrival:
                about["arrival_error"] = {"sigma_m": arrival[0], "sigma_deg": arrival[1]}
            if localisation is not None:  # absent: the arrival's share (sessions unchanged)
                about["localisation_error"] = dict(
                    zip(("sigma_m", "sigma_deg"), localisation, strict=True)
                )
            if table_error is not None:  # absent: the default table (sessions unchanged)
                about["table_error_deg"] = table_error
            if color_shift is not None:  # absent: exact registration (sessions unchanged)
                about["color_shift_px"] = list(color_shift)
            if args.color_holes:
                about["color_holes"] = True
            if depth_offset is not None:  # absent: no offset (sessions unchanged)
                about["depth_offset_m"] = depth_offset
            if sunlight is not None:  # absent: no sun in the depth (sessions unchanged)
                about["sunlight"] = sunlight
            if color_noise is not None:  # absent: brightness noise only (sessions unchanged)
                about["color_noise_levels"] = color_noise
            if veil is not None:  # absent: single flying pixels (sessions unchanged)
                about["veil_px"] = veil
            if clods is not None:  # absent: no clods (sessions unchanged)
                about["clods_per_m2"] = clods
            if clod_size is not None:  # absent: clods up to 8 cm across (sessions unchanged)
                about["clod_size_cm"] = clod_size
            if dry_tips is not None:  # absent: green to the tips (sessions unchanged)
                about["dry_tips_cm"] = dry_tips
            if grounded is not None:  # absent: no leaf down to the soil (sessions unchanged)
                about["grounded_leaves"] = grounded
            if late is not None:  # absent: every plant came up with the others (unchanged)
                about["late_plants"] = late
            if args.depth_only:
                about["depth_only"] = True
            if args.lens_distortion:  # absent: undistorted images (sessions unchanged)
                from devices.camera.frames import KINECT_V2_DISTORTION

                about["lens_distortion"] = list(KINECT_V2_DISTORTION)
            if camera:  # absent: the paper's rig (sessions unchanged)
                about["camera"] = camera
            if spacing is not None:  # absent: the paper's plan (sessions unchanged)
                about["station_spacing_m"] = spacing
            if tilt is not None:  # absent: the soil's slope alone (sessions unchanged)
                about["max_base_tilt_deg"] = tilt
            plan = simulated_plan(rig, sown=args.scene == "plot")
            count = write_session(args.out, world, stations, views, seed, about, errors, plan)
        if args.scene == "checkerboard" and shots:
            write_intrinsics_images(args.out, seed, shots)
    except OSError as error:
        raise FieldappError(
            f"--out: cannot write {error.filename or args.out}: {error.strerror}"
        ) from None
    print(f"{args.out}: {count} captures of the {args.scene} scene (truth in truth.json)")
    return 0


def _write_turntable(
    out: Path,
    seed: int,
    day: int,
    views: list[int],
    depth_only: bool,
    color_holes: bool,
    color_noise: float | None = None,
) -> int:
    from fieldapp.cli._simulate_turntable import write_turntable_session

    return write_turntable_session(
        out, seed, day, views, depth_only, color_holes=color_holes, color_noise=color_noise
    )


def build_world(
    scene_name: str,
    seed: int,
    day: int,
    rig: RigGeometry,
    plants: bool,
    stage: str = "seedling",
    plant_model: str = "distichous",
    max_lean_deg: float | None = None,
    depth_offset_m: float | None = None,
    sunlight: float | None = None,
    leaf_width: float | None = None,
    lens_distortion: bool = False,
    *,
    color_noise: float | None = None,
    veil_px: int | None = None,
    clods_per_m2: float | None = None,
    clod_size_m: float | None = None,
    dry_tips_m: float | None = None,
    grounded_leaves: float | None = None,
    late_plants: float | None = None,
) -> SimWorld:
    from devices.sim.calibration_scenes import checkerboard_scene
    from devices.sim.render import SensorModel
    from devices.sim.scene import (
        bare_soil_scene,
        plot_scene,
        soil_for_plot,
        spheres_scene,
    )
    from devices.sim.sensor import FULL_SUN_IR
    from devices.sim.world import SimWorld

    layout = plant_layout(rig)
    soil = soil_for_plot(max(rig.plot_half_extent_m, layout.half_extent_m))
    if scene_name == "plot":
        scene = plot_scene(
            seed,
            day,
            layout,
            soil,
            stage,
            plant_model,
            max_lean_deg,
            leaf_width or 1.0,
            clods_per_m2 or 0.0,
            grounded_leaves or 0.0,
            late_plants or 0.0,
            clod_size_m,
            dry_tips_m or 0.0,
        )
    elif scene_name == "spheres":
        scene = spheres_scene(seed, day, plants, layout, soil)
    elif scene_name == "soil":
        scene = bare_soil_scene(seed, soil)
    else:
        scene = checkerboard_scene(seed, rig)
    sensor = SensorModel(
        depth_offset_m=depth_offset_m or 0.0,
        sun_ir=(sunlight or 0.0) * FULL_SUN_IR,
        color_noise=color_noise or 0.0,
        veil_px=veil_px or 0,
    )
    from devices.camera.frames import KINECT_V2_DISTORTION, KINECT_V2_PAPER

    intrinsics = KINECT_V2_PAPER
    if lens_distortion:
        intrinsics = replace(KINECT_V2_PAPER, distortion=KINECT_V2_DISTORTION)
    return SimWorld(scene, rig, intrinsics, seed=seed, sensor=sensor)


def plant_layout(rig: RigGeometry) -> PlotLayout:
    """Where the plants of ``rig``'s plot stand: as on the default plan of its grid (stations
    1.6 m apart), wherever its stations stand (``--station-spacing``)."""
    from devices.sim.rig import RigGeometry
    from devices.sim.scene import PlotLayout

    return PlotLayout.for_stations(rig.grid, RigGeometry().station_spacing_m)


def simulated_plan(rig: RigGeometry, sown: bool = True) -> dict[str, Any]:
    """The session's ``plan`` as a mission would write it (session-format spec, map frame): the
    stations' nominal map poses, the views, and (``sown``) the planting grid the plot was sown
    on (rows along the map's x axis, row 1 column 1 at the plants' lowest x and y; the
    simulated plants stand within a few cm of its nodes)."""
    import numpy as np

    stations = [
        {"number": s, "x_m": p.x_m, "y_m": p.y_m, "yaw_deg": p.yaw_deg}
        for s, p in ((s, rig.station_pose(s)) for s in rig.stations)
    ]
    plan: dict[str, Any] = {
        "stations": stations,
        "views": {"count": rig.views, "step_deg": rig.view_step_deg},
    }
    if not sown:
        return plan
    layout = plant_layout(rig)
    T_map_field = np.linalg.inv(rig.T_field_map)
    first_field = -np.array([layout.cols - 1, layout.rows - 1]) * layout.spacing_m / 2
    origin = T_map_field[:2, :2] @ first_field + T_map_field[:2, 3]
    return plan | {
        "planting_grid": {
            "rows": layout.rows,
            "columns": layout.cols,
            "row_spacing_m": layout.spacing_m,
            "plant_spacing_m": layout.spacing_m,
            "origin": {"x": round(float(origin[0]), 9), "y": round(float(origin[1]), 9)},
            "row_direction_deg": 0.0,
        },
    }


def nominal_calibration(world: SimWorld) -> Calibration:
    """The rig's pre-calibration over all the plan's stations (reference: the centre one, 5 on
    the 3 x 3 plan), with the sensor's depth offset when it has one."""
    from fieldapp.mission.calibration import rig_calibration

    rig = world.rig
    poses = {s: rig.station_pose(s) for s in rig.stations}
    calibration = rig_calibration(world, poses, rig.reference_station, rig.view_step_deg)
    offset_m = world.renderer.sensor.depth_offset_m
    if offset_m:  # the unit's depth offset, as a calibration that measured it holds it
        camera = calibration.depth_camera.model_copy(update={"depth_offset_m": offset_m})
        calibration = calibration.model_copy(update={"depth_camera": camera})
    return calibration


def write_session(
    folder: Path,
    world: SimWorld,
    stations: list[int],
    views: list[int],
    seed: int,
    about: dict[str, Any],
    errors: StopErrors | None = None,
    plan: dict[str, Any] | None = None,
) -> int:
    """Simulate and write the session (with the mission ``plan`` when given); returns the
    number of captures written."""
    from devices.sim.survey import survey
    from devices.sim.truth import truth_document
    from fieldapp.io.durable import write_json_durably
    from fieldapp.io.writer import SessionWriter

    stage = "" if about.get("stage", "seedling") == "seedling" else f"-{about['stage']}"
    model = f"-{about['plant_model']}" if "plant_model" in about else ""
    session_id = f"sim-{about['scene']}-seed{seed}-day{about['day']}{stage}{model}"
    extra: dict[str, Any] = {"simulated": about} | ({"plan": plan} if plan else {})
    writer = SessionWriter.create(folder, session_id, nominal_calibration(world), extra=extra)
    truths = []
    tag_boards = bool(world.scene.boards)
    with ThreadPoolExecutor(max_workers=1) as saver:  # encode and write while rendering the next
        pending: deque[Future[Any]] = deque()
        for capture in survey(world, stations, views, seed, errors, tag_boards=tag_boards):
            pending.append(
                saver.submit(
                    save_capture,
                    writer,
                    capture,
                    bool(about.get("depth_only")),
                    about.get("color_shift_px"),
                    world.intrinsics if about.get("color_holes") else None,
                )
            )
            truths.append(capture.truth())
            while len(pending) > 2:
                pending.popleft().result()
        for future in pending:
            future.result()
    document = truth_document(world.scene, truths, world.rig, world.intrinsics, about)
    write_json_durably(folder / "truth.json", document)
    return len(truths)


def save_capture(
    writer: SessionWriter,
    capture: SimCapture,
    depth_only: bool = False,
    color_shift_px: Sequence[int] | None = None,
    holes_of: Intrinsics | None = None,
) -> None:
    """Write one simulated capture as the devices would have reported it (without its colour
    image when ``depth_only``; with it registered ``color_shift_px`` (DX, DY) off the depth,
    :func:`devices.sim.sensor.misregistered`; with ``holes_of``, the depth camera's
    intrinsics, black where libfreenect2's registration gives no colour,
    :func:`devices.sim.sensor.registered_as_libfreenect2`)."""
    from devices.sim.sensor import misregistered, registered_as_libfreenect2
    from fieldapp.io.session import BasePose

    pose = capture.reported_pose
    color = capture.frame.color
    if color_shift_px is not None and color is not None:
        color = misregistered(color, *color_shift_px)
    if holes_of is not None and color is not None:
        color = registered_as_libfreenect2(color, capture.frame.depth_m, holes_of)
    writer.add_capture(
        capture.station,
        capture.view,
        capture.frame.depth_m,
        None if depth_only else color,
        ir=capture.frame.ir,
        angle_deg=capture.reported_angle_deg,
        base_pose=BasePose(x=pose.x_m, y=pose.y_m, yaw_deg=pose.yaw_deg),
        target=capture.target,
    )
    log.debug("station %d view %d %s", capture.station, capture.view, capture.target or "")


def write_intrinsics_images(folder: Path, seed: int, count: int) -> None:
    """IR images of the intrinsics board under ``folder/intrinsics/``, listed in truth.json."""
    from devices.sim.calibration_scenes import INTRINSICS_BOARD, intrinsics_images
    from fieldapp.io.durable import write_bytes_durably, write_json_durably
    from fieldapp.io.images import encode_png
    from fieldapp.io.jsonfile import read_json

    entries = []
    for index, (T_camera_board, ir) in enumerate(intrinsics_images(count, seed)):
        name = f"intrinsics/ir-{index:02d}.png"
        write_bytes_durably(folder / name, encode_png(ir))
        entries.append({"ir": name, "T_camera_board": T_camera_board.tolist()})
    document = read_json(folder / "truth.json")
    document["intrinsics_images"] = {"board": INTRINSICS_BOARD.name, "images": entries}
    document["boards"].append(
        {
            "name": INTRINSICS_BOARD.name,
            "inner_cols": INTRINSICS_BOARD.inner_cols,
            "inner_rows": INTRINSICS_BOARD.inner_rows,
            "square_m": INTRINSICS_BOARD.square_m,
            "margin_squares": INTRINSICS_BOARD.margin_squares,
        }
    )
    write_json_durably(folder / "truth.json", document)
