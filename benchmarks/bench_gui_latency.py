"""GUI-thread stalls during a mission with the live view open (target: <= 50 ms).

Opens the main window on simulated devices (real-time simulators, as in a demo), shows the
Live page, starts the paper's 3 x 3 mission, and for ``--seconds`` measures the event loop's
latency: a QTimer asks to fire every 5 ms; each late firing is a stall of the GUI thread (the
time it could not react). Prints the distribution and the worst stalls, with what the mission
was doing. Run it offscreen (default) or under Xvfb to include the OpenGL 3D view:

    QT_QPA_PLATFORM=offscreen .venv/bin/python benchmarks/bench_gui_latency.py
    xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/python benchmarks/bench_gui_latency.py
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

TICK_MS = 5
TARGET_MS = 50.0
CPU_DURING_STALLS: list[tuple[float, float, float]] = []
"""(stall, CPU time of the whole process, CPU time of the GUI thread) in ms, per stall over
the target: a stall during which the process got little CPU was the machine's doing (other
processes on the shared cores), not the application's."""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=40.0, help="measuring time (40)")
    parser.add_argument("--instant", action="store_true", help="instant simulators (stress)")
    parser.add_argument(
        "--switch-ms", type=float, help="GIL switch interval (default: the app's, 1 ms)"
    )
    args = parser.parse_args()
    from ui.app import tune_process

    tune_process()  # as `fieldapp gui` does
    if args.switch_ms:
        sys.setswitchinterval(args.switch_ms / 1000.0)
    if "DISPLAY" not in os.environ:
        os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

    from PySide6 import QtWidgets

    from fieldapp.settings import Settings
    from ui.app import build_window
    from ui.state import UiState

    app = QtWidgets.QApplication(sys.argv[:1])
    with tempfile.TemporaryDirectory() as tmp:
        settings = Settings()
        settings.paths.sessions_dir = Path(tmp) / "sessions"
        settings.devices.realtime_simulation = not args.instant
        window = build_window(
            settings, settings_path=Path(tmp) / "s.yaml", ui_state=UiState(Path(tmp) / "ui.ini")
        )
        window.resize(1400, 900)
        window.show()
        hub = window.context.hub
        hub.connect_devices(settings.devices)
        wait(app, lambda: hub.connected, 60.0, "connecting")
        window.show_page("live")
        mission = window.pages["mission"]
        mission.start()  # type: ignore[attr-defined]
        wait(app, lambda: mission.controller.runner is not None, 30.0, "starting")  # type: ignore[attr-defined]
        stalls, steps = measure(app, window, args.seconds)
        live = window.pages["live"]
        shown, captured = live.frames_shown, mission.progress.captured  # type: ignore[attr-defined]
        cloud = "3D view on" if live.cloud.available else f"3D view off ({live.cloud.problem})"  # type: ignore[attr-defined]
        window.emergency_stop()  # STOP, then close without the question
        wait(app, lambda: not mission.busy, 30.0, "stopping")  # type: ignore[attr-defined]
        window.close()
    report(stalls, steps, args, shown, captured, cloud, QtWidgets.QApplication.platformName())
    return 0 if max(stalls) <= TARGET_MS else 1


def wait(app: object, condition: object, timeout_s: float, what: str) -> None:
    from PySide6 import QtCore

    deadline = time.monotonic() + timeout_s
    while not condition():  # type: ignore[operator]
        if time.monotonic() > deadline:
            raise SystemExit(f"timed out {what}")
        QtCore.QCoreApplication.processEvents(QtCore.QEventLoop.ProcessEventsFlag.AllEvents, 20)
        time.sleep(0.005)


def measure(app: object, window: object, seconds: float) -> tuple[list[float], list[str]]:
    """Late firings of a 5 ms timer (ms), and the mission's step at each."""
    from PySide6 import QtCore

    stalls: list[float] = []
    steps: list[str] = []
    last = [time.perf_counter()]
    step_label = window.pages["mission"].progress.step  # type: ignore[attr-defined]

    cpu_last = [time.process_time(), time.thread_time()]

    def tick() -> None:
        now, process_s, thread_s = time.perf_counter(), time.process_time(), time.thread_time()
        stall_ms = max(0.0, 1000.0 * (now - last[0]) - TICK_MS)
        stalls.append(stall_ms)
        steps.append(step_label.text())
        if stall_ms > TARGET_MS:
            CPU_DURING_STALLS.append(
                (stall_ms, 1000.0 * (process_s - cpu_last[0]), 1000.0 * (thread_s - cpu_last[1]))
            )
        last[0] = now
        cpu_last[:] = [process_s, thread_s]

    watcher = StallWatcher(last)
    timer = QtCore.QTimer()
    timer.setTimerType(QtCore.Qt.TimerType.PreciseTimer)
    timer.timeout.connect(tick)
    timer.start(TICK_MS)
    loop = QtCore.QEventLoop()
    QtCore.QTimer.singleShot(int(seconds * 1000), loop.quit)
    cpu0 = resource.getrusage(resource.RUSAGE_SELF)
    watcher.start()
    loop.exec()
    timer.stop()
    watcher.stop()
    watcher.print_top()
    cpu1 = resource.getrusage(resource.RUSAGE_SELF)
    cpu_s = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
    print(f"process CPU {cpu_s:.1f} s in {seconds:.0f} s of wall time (all threads)")
    return stalls[1:], steps[1:]


class StallWatcher:
    """Samples the GUI thread's stack (and what the other threads run) whenever the timer has
    not fired for more than ``TARGET_MS``: where the GUI thread is stuck."""

    def __init__(self, last: list[float]) -> None:
        import collections
        import threading

        self.last = last
        self.samples: collections.Counter[str] = collections.Counter()
        self.others: collections.Counter[str] = collections.Counter()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="stall-watcher", daemon=True)
        self._main = threading.main_thread().ident

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()

    def _run(self) -> None:
        import threading
        import traceback

        while not self._stop.wait(0.01):
            if 1000.0 * (time.perf_counter() - self.last[0]) < TARGET_MS:
                continue
            frames = sys._current_frames()
            main = frames.get(self._main or 0)
            if main is None:
                continue
            stack = traceback.extract_stack(main)[-4:]
            where = " < ".join(
                f"{f.name} ({Path(f.filename).name}:{f.lineno})" for f in reversed(stack)
            )
            self.samples[where] += 1
            for ident, frame in frames.items():
                if ident not in (self._main, threading.get_ident()):
                    top = traceback.extract_stack(frame)[-1]
                    self.others[f"{top.name} ({Path(top.filename).name}:{top.lineno})"] += 1

    def print_top(self, count: int = 6) -> None:
        total = sum(self.samples.values())
        if total:
            print(f"where the GUI thread was during stalls ({total} samples of 10 ms):")
        for where, n in self.samples.most_common(count):
            print(f"  {n:4d}  {where}")
        if total:
            print("what the other threads were running meanwhile:")
        for where, n in self.others.most_common(count + 4):
            print(f"  {n:4d}  {where}")


def report(stalls: list[float], steps: list[str], args: argparse.Namespace, shown: int,
           captured: int, cloud: str, platform: str) -> None:  # fmt: skip
    values = np.array(stalls)
    mode = "instant" if args.instant else "real-time"
    switch_ms = 1000.0 * sys.getswitchinterval()
    print(f"platform {platform}, {mode} simulators, {cloud}, GIL switch {switch_ms:g} ms")
    print(f"{len(values)} timer firings in {args.seconds:.0f} s; {shown} frames shown, "
          f"{captured} views captured")  # fmt: skip
    print("GUI-thread stall (late timer firing), ms: "
          f"median {np.median(values):.1f}, p99 {np.percentile(values, 99):.1f}, "
          f"p99.9 {np.percentile(values, 99.9):.1f}, max {values.max():.1f} "
          f"(target <= {TARGET_MS:.0f})")  # fmt: skip
    print(f"stalls over 20 ms: {(values > 20).sum()}, over 50 ms: {(values > 50).sum()}")
    for index in np.argsort(values)[-5:][::-1]:
        print(f"  {values[index]:6.1f} ms during: {steps[index] or '-'}")
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    if CPU_DURING_STALLS:
        starved = [s for s in CPU_DURING_STALLS if s[1] < 0.5 * s[0]]
        print(f"stalls over {TARGET_MS:.0f} ms during which the whole process got under half "
              f"a core: {len(starved)} of {len(CPU_DURING_STALLS)} (the machine)")  # fmt: skip
        print("  stall ms / process CPU ms / GUI-thread CPU ms:")
        for stall, process, thread in sorted(CPU_DURING_STALLS, reverse=True)[:6]:
            print(f"  {stall:7.1f} / {process:7.1f} / {thread:7.1f}")


if __name__ == "__main__":
    sys.exit(main())
