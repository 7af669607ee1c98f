"""Soak test of the field GUI: N minutes on the Live page and through three simulated missions
with STOPs; reports crashes, memory growth and GUI stalls.

    .venv/bin/python benchmarks/soak_gui.py --minutes 30 --out /tmp/soak

The parent process runs the GUI in a child (offscreen unless ``DISPLAY`` is set; run under
``xvfb-run -a`` for the OpenGL view) and reports how the child ended: a crash (a signal such as
SIGABRT from ``Fatal Python error``) or a non-zero exit is a failure. The child opens the real
window on simulated devices in real time (the demo's settings), connects, shows the Live page
and, at a quarter, a half and three quarters of the run, drives a mission on the Mission page
like an operator: Start, then STOP at a seeded random capture (the second mission is paused
first and stopped while paused), resume the session to its end, back to the Live page. It
samples every ``--sample-s`` seconds: resident memory, threads, frames shown, the load average.
GUI stalls are measured throughout by a 20 ms QTimer (each late firing is a stall). STOP is
timed from the press to the page leaving STOPPING (``stop_s``; the runner's own figure is
``landed_s``).

The report (stdout and ``OUT/soak.json``): crashes, uncaught exceptions, memory at the end of
the first minute and at the end with the growth rate over the second half (MB/h), stalls (worst,
99th percentile, count over 250 ms), frames shown per second on the Live page, each mission's
outcome and STOP times, and the machine's load.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

TICK_MS = 20
STALL_MS = 250.0
PLAN_STATIONS = ((5, 1.6, 1.6), (6, 3.2, 1.6), (3, 3.2, 0.0))


# --- the parent ---------------------------------------------------------------------------


def parent(args: argparse.Namespace) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ)
    if "DISPLAY" not in env:
        env["QT_QPA_PLATFORM"] = "offscreen"
    command = [sys.executable, "-X", "faulthandler", __file__, "--child", *sys.argv[1:]]
    started_s = time.monotonic()
    with open(out / "child.log", "w") as log_file:
        child = subprocess.run(command, env=env, stdout=log_file, stderr=subprocess.STDOUT)
    elapsed_s = time.monotonic() - started_s
    code = child.returncode
    summary: dict[str, Any] = {}
    if (out / "soak.json").exists():
        summary = json.loads((out / "soak.json").read_text())
    crashed = code != 0
    how = "exit 0" if code == 0 else describe_exit(code)
    print(f"child ended after {elapsed_s / 60:.1f} min: {how}")
    if crashed:
        print(f"CRASH or failure: see {out / 'child.log'} (last lines below)")
        lines = (out / "child.log").read_text(errors="replace").splitlines()
        print("\n".join(lines[-25:]))
    if summary:
        print_summary(summary)
    summary["exit"] = how
    (out / "soak.json").write_text(json.dumps(summary, indent=1))
    return 1 if crashed or summary.get("exceptions") else 0


def describe_exit(code: int) -> str:
    if code < 0:
        return f"killed by {signal.Signals(-code).name}"
    return f"exit {code}"


def print_summary(s: dict[str, Any]) -> None:
    memory, stalls = s["memory_mb"], s["stalls_ms"]
    print(f"run: {s['minutes']:.1f} min, load average {s['load_start']} -> {s['load_end']}")
    print(f"uncaught exceptions: {len(s['exceptions'])}")
    print(
        f"memory (RSS): {memory['after_1_min']:.0f} MB after 1 min, {memory['end']:.0f} MB at "
        f"the end, peak {memory['peak']:.0f} MB; second half {memory['slope_mb_per_h']:+.1f} MB/h"
    )
    print(f"threads: {s['threads_start']} -> {s['threads_end']}")
    print(
        f"GUI stalls: worst {stalls['max']:.0f} ms, p99 {stalls['p99']:.0f} ms, "
        f"{stalls['over_250']} over 250 ms in {stalls['ticks']} ticks"
    )
    print(f"live preview: {s['live_fps']:.1f} frames shown per second on the Live page")
    for mission in s["missions"]:
        print(
            f"mission {mission['number']}: STOP at capture {mission['stop_at']} "
            f"({mission['how']}): page left STOPPING after {mission['stop_s']:.2f} s, runner "
            f"landed in {mission['landed_s']}, {mission['stopped_outcome']}; resumed -> "
            f"{mission['final_outcome']} ({mission['captured']} captures)"
        )


# --- the child: the GUI -----------------------------------------------------------------------


class StallMeter:
    """A QTimer every TICK_MS on the GUI thread; a late firing is a stall."""

    def __init__(self) -> None:
        from PySide6 import QtCore

        self.gaps_ms: list[float] = []
        self._last_s = time.monotonic()
        self.timer = QtCore.QTimer()
        self.timer.setTimerType(QtCore.Qt.TimerType.PreciseTimer)
        self.timer.timeout.connect(self.tick)
        self.timer.start(TICK_MS)

    def tick(self) -> None:
        now_s = time.monotonic()
        self.gaps_ms.append(max(0.0, (now_s - self._last_s) * 1000.0 - TICK_MS))
        self._last_s = now_s

    def summary(self) -> dict[str, float]:
        import numpy as np

        gaps = np.asarray(self.gaps_ms or [0.0])
        return {
            "max": float(gaps.max()),
            "p99": float(np.percentile(gaps, 99)),
            "over_250": int((gaps > STALL_MS).sum()),
            "ticks": len(gaps),
        }


def rss_mb() -> float:
    pages = int(Path("/proc/self/statm").read_text().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 1e6


def pump(condition: Callable[[], bool] = lambda: False, timeout_s: float = 1.0) -> bool:
    from PySide6 import QtCore

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        QtCore.QCoreApplication.processEvents(QtCore.QEventLoop.ProcessEventsFlag.AllEvents, 20)
        if condition():
            return True
        time.sleep(0.005)
    return condition()


class Soak:
    def __init__(self, args: argparse.Namespace, window: Any, out: Path) -> None:
        import numpy as np

        self.args, self.window, self.out = args, window, out
        self.rng = np.random.default_rng(args.seed)
        self.stalls = StallMeter()
        self.samples: list[dict[str, Any]] = []
        self.missions: list[dict[str, Any]] = []
        self.exceptions: list[str] = []
        self.live_frames = 0
        self.live_seconds = 0.0
        self.started_s = time.monotonic()
        self._next_sample_s = 0.0

    @property
    def elapsed_s(self) -> float:
        return time.monotonic() - self.started_s

    def sample(self) -> None:
        if self.elapsed_s < self._next_sample_s:
            return
        self._next_sample_s = self.elapsed_s + self.args.sample_s
        preview = self.preview()
        row = {
            "t_s": round(self.elapsed_s, 1),
            "rss_mb": round(rss_mb(), 1),
            "threads": threading.active_count(),
            "frames_shown": preview.frames_shown,
            "load": os.getloadavg()[0],
        }
        self.samples.append(row)
        with open(self.out / "samples.jsonl", "a") as samples:
            samples.write(json.dumps(row) + "\n")

    def preview(self) -> Any:
        from ui.live.preview import LivePreview

        live = self.window.pages["live"]
        return live if isinstance(live, LivePreview) else live.findChild(LivePreview)

    def wait(self, condition: Callable[[], bool], timeout_s: float) -> bool:
        deadline_s = time.monotonic() + timeout_s
        while time.monotonic() < deadline_s:
            if pump(condition, 0.5):
                return True
            self.sample()
        return condition()

    def live_until(self, until_s: float) -> None:
        self.window.show_page("live")
        preview = self.preview()
        shown, since_s = preview.frames_shown, time.monotonic()
        self.wait(lambda: self.elapsed_s >= until_s, max(0.0, until_s - self.elapsed_s) + 1.0)
        self.live_frames += preview.frames_shown - shown
        self.live_seconds += time.monotonic() - since_s

    def mission(self, number: int) -> None:
        from fieldapp.mission.events import MissionState
        from fieldapp.mission.plan import MissionPlan, StationPlan, ViewPlan

        window = self.window
        window.show_page("mission")
        page = window.pages["mission"]
        stations = [StationPlan(number=n, x_m=x, y_m=y) for n, x, y in PLAN_STATIONS]
        plan = MissionPlan(name=f"soak{number}", stations=stations, views=ViewPlan(count=4),
                           frames_per_capture=3, settle_s=0.2)  # fmt: skip
        page.editor.set_plan(plan)
        total = len(plan.capture_keys())
        stop_at = int(self.rng.integers(1, total - 1))
        how = "paused" if number == 2 else "running"
        record: dict[str, Any] = {"number": number, "stop_at": stop_at, "how": how}
        page.start()
        if not self.wait(lambda: page.progress.captured >= stop_at, 600.0):
            raise RuntimeError(f"mission {number}: no capture {stop_at} within 10 min")
        if how == "paused":
            page.toggle_pause()
            self.wait(lambda: page.controller.state is MissionState.PAUSED, 60.0)
        pressed_s = time.monotonic()
        window.emergency_stop()
        if not self.wait(lambda: page.result is not None, 60.0):
            raise RuntimeError(f"mission {number}: STOP did not land within 60 s")
        record["stop_s"] = time.monotonic() - pressed_s
        runner = page.controller.runner
        latency = None if runner is None else runner.stop_latency_s
        record["landed_s"] = "?" if latency is None else f"{latency:.3f} s"
        record["stopped_outcome"] = page.result.outcome.value
        folder = page.controller.folder
        self.wait(lambda: not page.busy, 30.0)
        page.resume(folder)
        self.wait(lambda: page.result is None, 30.0)
        if not self.wait(lambda: page.result is not None and not page.busy, 900.0):
            raise RuntimeError(f"mission {number}: the resumed mission did not end")
        record["final_outcome"] = page.result.outcome.value
        record["captured"] = page.result.captured
        self.missions.append(record)
        print(f"mission {number}: {record}", flush=True)

    def run(self) -> None:
        hub = self.window.context.hub
        hub.connect_devices(self.window.context.settings.devices)
        if not self.wait(lambda: hub.connected, 120.0):
            raise RuntimeError("the simulated devices did not connect within 2 min")
        total_s = self.args.minutes * 60.0
        for number, fraction in enumerate((0.25, 0.5, 0.75), start=1):
            self.live_until(total_s * fraction)
            self.mission(number)
        self.live_until(total_s)

    def summary(self, rss_start: float) -> dict[str, Any]:
        import numpy as np

        after_1 = [s["rss_mb"] for s in self.samples if s["t_s"] >= 60.0] or [rss_start]
        half = [s for s in self.samples if s["t_s"] >= self.elapsed_s / 2]
        slope = 0.0
        if len(half) >= 3:
            t_h = np.array([s["t_s"] for s in half]) / 3600.0
            slope = float(np.polyfit(t_h, [s["rss_mb"] for s in half], 1)[0])
        return {
            "minutes": self.elapsed_s / 60.0,
            "exceptions": self.exceptions,
            "memory_mb": {
                "start": rss_start,
                "after_1_min": after_1[0],
                "end": rss_mb(),
                "peak": max([s["rss_mb"] for s in self.samples] or [rss_start]),
                "slope_mb_per_h": slope,
            },
            "threads_start": self.samples[0]["threads"] if self.samples else 0,
            "threads_end": threading.active_count(),
            "stalls_ms": self.stalls.summary(),
            "live_fps": self.live_frames / self.live_seconds if self.live_seconds else 0.0,
            "missions": self.missions,
            "load_start": self.samples[0]["load"] if self.samples else None,
            "load_end": os.getloadavg()[0],
        }


def child(args: argparse.Namespace) -> int:
    from PySide6 import QtWidgets

    from fieldapp.settings import Settings
    from ui.app import build_window, tune_process
    from ui.state import UiState

    out = Path(args.out)
    (out / "samples.jsonl").unlink(missing_ok=True)
    tune_process()
    app = QtWidgets.QApplication(sys.argv[:1])
    rss_start = rss_mb()
    with tempfile.TemporaryDirectory() as tmp:
        settings = Settings()
        settings.paths.sessions_dir = Path(tmp) / "sessions"
        settings.devices.realtime_simulation = True
        window = build_window(
            settings, settings_path=Path(tmp) / "s.yaml", ui_state=UiState(Path(tmp) / "ui.ini")
        )
        window.resize(1440, 900)
        window.show()
        soak = Soak(args, window, out)

        def on_exception(kind: type[BaseException], error: BaseException, tb: Any) -> None:
            soak.exceptions.append("".join(traceback.format_exception(kind, error, tb)))
            sys.__excepthook__(kind, error, tb)

        sys.excepthook = on_exception
        try:
            soak.run()
        except Exception:  # the soak's own failure is reported, then the window closes
            soak.exceptions.append(traceback.format_exc())
            traceback.print_exc()
        summary = soak.summary(rss_start)
        (out / "soak.json").write_text(json.dumps(summary, indent=1))
        window.close()
        window.deleteLater()
        pump(timeout_s=1.0)
    del app
    return 1 if soak.exceptions else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=30.0, help="length of the run (30)")
    parser.add_argument("--out", default="soak-out", help="folder for the log and figures")
    parser.add_argument("--seed", type=int, default=0, help="where the STOPs fall (0)")
    parser.add_argument("--sample-s", type=float, default=10.0, help="sampling period (10 s)")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    return child(args) if args.child else parent(args)


if __name__ == "__main__":
    sys.exit(main())
