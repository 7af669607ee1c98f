"""``fieldapp camera``: open a depth camera and print what it is, grab a quiet frame, or
stream for a while and print the measured rate and the capture quality figures."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fieldapp.errors import FieldappError

if TYPE_CHECKING:
    from devices.camera.base import DepthCamera
    from devices.camera.frames import Frame
    from devices.camera.quality import QualityReport

BACKENDS = ("sim", "replay", "kinect2", "realsense")
PREVIEW_PERIOD_S = 0.1
"""How often ``stream`` looks at the newest frame (a preview's pace, not the camera's)."""


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "camera",
        help="open the depth camera: info, grab a quiet frame, or stream and measure",
        description="Open a depth camera backend and print its intrinsics and serial (info), "
        "write a quiet frame (grab), or stream for a while and print the measured frame rate, "
        "dropped frames and capture quality (stream). Default backend: the settings'.",
    )
    parser.add_argument("--backend", choices=BACKENDS, help="default: devices.camera_backend")
    parser.add_argument("--session", type=Path, help="replay: the session folder to play")
    parser.add_argument("--serial", help="kinect2/realsense: which device (default: first)")
    parser.add_argument("--recording", type=Path, help="realsense: play an SDK recording")
    parser.add_argument("--fast", action="store_true", help="sim/replay: not in real time")
    actions = parser.add_subparsers(dest="action", metavar="ACTION")
    actions.add_parser("info", help="print backend, model, serial and intrinsics (default)")
    grab = actions.add_parser("grab", help="write a quiet frame (median of --frames) to --out")
    grab.add_argument("--out", type=Path, required=True, help="folder for the images")
    grab.add_argument("--frames", type=int, default=5, help="frames in the median (1-100)")
    stream = actions.add_parser("stream", help="stream for --seconds and print the figures")
    stream.add_argument("--seconds", type=float, default=5.0, help="how long (0-3600 s)")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from devices.camera.base import CameraError

    try:
        camera = build_camera(args)
        with camera:
            print_info(camera)
            if args.action == "grab":
                grab(camera, args.out, args.frames)
            elif args.action == "stream":
                stream(camera, args.seconds)
    except CameraError as error:
        raise FieldappError(str(error)) from None
    return 0


def build_camera(args: argparse.Namespace) -> DepthCamera:
    from devices.camera.factory import make_camera
    from fieldapp.settings import load_settings

    devices = load_settings().devices
    backend = args.backend or devices.camera_backend
    session = args.session or devices.replay_session
    if backend == "replay" and session is None:
        raise FieldappError("--session: the replay backend needs a session folder")
    realtime = devices.realtime_simulation and not args.fast
    return make_camera(
        backend,
        realtime=realtime,
        session=session,
        loop=True,
        serial=args.serial,
        recording=args.recording,
    )


def print_info(camera: DepthCamera) -> None:
    info, k = camera.info, camera.intrinsics
    kind = " (simulated)" if info.simulated else ""
    print(f"camera: {info.backend}{kind}, {info.model}, serial {info.serial}")
    print(f"intrinsics: {k.width} x {k.height} px, fx {k.fx:.2f} fy {k.fy:.2f} ", end="")
    print(f"cx {k.cx:.2f} cy {k.cy:.2f}, distortion {list(k.distortion)}")


def print_quality(report: QualityReport) -> None:
    from devices.camera.quality import QualityThresholds

    print(
        f"quality: fill {report.fill_rate:.1%} of the crop region ({report.crop_fraction:.0%} "
        f"of the image), flying pixels {report.flying_ratio:.2%}, over-exposed "
        f"{report.overexposed:.1%}, under-exposed {report.underexposed:.1%}, "
        f"age {1000 * report.age_s:.0f} ms"
    )
    problems = report.problems(QualityThresholds())
    print("quality: go" if not problems else "quality: NO GO: " + "; ".join(problems))


def grab(camera: DepthCamera, out: Path, frames: int) -> None:
    from devices.camera.quality import assess

    if not 1 <= frames <= 100:
        raise FieldappError(f"--frames: {frames} is outside 1..100")
    if out.exists() and not out.is_dir():
        raise FieldappError(f"--out: {out} exists and is not a folder")
    frame = camera.capture(frames)
    report = assess(frame, camera.intrinsics)
    write_frame(out, frame, camera, report)
    print_quality(report)
    print(f"{out}: depth.png, color.png{', ir.png' if frame.ir is not None else ''}, frame.json")


def write_frame(out: Path, frame: Frame, camera: DepthCamera, report: QualityReport) -> None:
    """depth.png (16-bit mm), color.png (RGB), ir.png (16-bit) and frame.json."""
    from dataclasses import asdict

    from fieldapp.io.durable import write_bytes_durably, write_json_durably
    from fieldapp.io.images import depth_m_to_units, encode_png

    write_bytes_durably(out / "depth.png", encode_png(depth_m_to_units(frame.depth_m, 1000.0)))
    write_bytes_durably(out / "color.png", encode_png(frame.color, rgb=True))
    if frame.ir is not None:
        write_bytes_durably(out / "ir.png", encode_png(frame.ir))
    document = {
        "camera": asdict(camera.info),
        "intrinsics": {**asdict(camera.intrinsics), "depth_scale": 1000.0},
        "frames_combined": frame.meta.get("frames_combined", 1),
        "quality": asdict(report),
        "meta": json.loads(json.dumps(frame.meta, default=str)),
    }
    write_json_durably(out / "frame.json", document)


def stream(camera: DepthCamera, seconds: float) -> None:
    from devices.camera.quality import assess
    from devices.camera.stream import FrameStream

    if not 0 < seconds <= 3600:
        raise FieldappError(f"--seconds: {seconds} is outside 0..3600")
    with FrameStream(camera) as frames:
        started = time.monotonic()
        latest = None
        while time.monotonic() - started < seconds:
            time.sleep(PREVIEW_PERIOD_S)
            latest = frames.latest() or latest
        stats = frames.stats()
        latest = frames.latest() or latest
    print(
        f"stream: {stats.frames} frames in {seconds:.1f} s, {stats.fps:.1f} fps, "
        f"{stats.overwritten} replaced unread, {stats.camera_dropped} dropped by the camera"
    )
    if latest is None:
        raise FieldappError("the camera delivered no frame")
    print_quality(assess(latest, camera.intrinsics))
