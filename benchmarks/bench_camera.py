"""Camera timings on this machine: the simulated Kinect's render and re-noise costs, the live
stream's rate into the latest-frame buffer while a slow consumer reads at its own pace, and
capture(5). Run by hand: ``.venv/bin/python benchmarks/bench_camera.py [--seconds S]``.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np

from devices.camera.quality import assess
from devices.camera.sim import SimCamera
from devices.camera.stream import FrameStream
from devices.sim.world import SimWorld


def median_ms(action: Callable[[], object], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        action()
        times.append(time.perf_counter() - started)
    return 1000 * statistics.median(times)


def bench_render(world: SimWorld) -> None:
    world.render()  # builds the BVH
    full = median_ms(lambda: world.render(np.random.default_rng(0)), 5)
    print(f"full noisy render (SimWorld.render): {full:.0f} ms/frame -> {1000 / full:.1f} fps")
    camera = SimCamera(world, realtime=False)
    with camera:
        camera.read_frame()
        angles = iter(range(1, 100))
        pose_change = median_ms(
            lambda: (world.set_table_angle_deg(next(angles)), camera.read_frame()), 3
        )
        world.set_table_angle_deg(0.0)
        camera.read_frame()
        renoise = median_ms(camera.read_frame, 30)
        capture = median_ms(lambda: camera.capture(5), 5)
    print(f"new rig pose (clean render + noise precompute): {pose_change:.0f} ms")
    print(f"re-noised frame: {renoise:.1f} ms -> {1000 / renoise:.0f} fps ceiling")
    print(f"capture(5), not real time: {capture:.0f} ms")


def bench_stream(world: SimWorld, seconds: float, consumer_period_s: float) -> None:
    camera = SimCamera(world, realtime=True)
    reads = 0
    with camera, FrameStream(camera) as stream:
        stream.next_frame(5.0)  # the first pose's render
        before = stream.stats()
        started = time.monotonic()
        while time.monotonic() - started < seconds:
            time.sleep(consumer_period_s)
            frame = stream.latest()
            if frame is not None:
                assess(frame, camera.intrinsics)  # the consumer's own work
                reads += 1
        after = stream.stats()
    frames = after.frames - before.frames
    print(
        f"real-time stream, consumer every {1000 * consumer_period_s:.0f} ms: "
        f"{frames} frames in {seconds:.1f} s = {frames / seconds:.1f} fps "
        f"(window {after.fps:.1f} fps), {after.camera_dropped - before.camera_dropped} ticks "
        f"skipped, {after.overwritten - before.overwritten} replaced unread, {reads} reads"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args()
    world = SimWorld.default()
    bench_render(world)
    for period_s in (0.1, 0.02):
        bench_stream(world, args.seconds, period_s)


if __name__ == "__main__":
    main()
