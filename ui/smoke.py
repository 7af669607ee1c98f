"""Self-test of an installed fieldapp (the bundle's ``--smoke-test``; ``python -m ui.smoke``).

Headless (Qt's offscreen platform) and touching none of the user's files, it:

1. opens the main window on simulated devices and checks it rendered;
2. connects the devices, checks all three are simulated and a depth frame arrives;
3. meanwhile, on a worker thread, simulates a tiny session (2 stations x 2 views of the
   default plot) into a temporary folder and reconstructs it through the core;
4. checks the plants found against the simulator's ground truth (``truth.json``);
5. closes the window (devices stopped) and returns 0, or 1 with one line naming the failed
   step, all within ``--timeout-s``.
"""

from __future__ import annotations

import argparse
import logging
import os
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Generic, TypeVar

if TYPE_CHECKING:
    from PySide6 import QtWidgets

    from ui.main_window import MainWindow

log = logging.getLogger(__name__)

T = TypeVar("T")

DEFAULT_TIMEOUT_S = 120.0
STATIONS = (5, 6)
"""Two neighbouring stations, so the global registration (ICP) runs too."""
VIEWS = (0, 4)
SEED = 0
MATCH_DISTANCE_M = 0.15
"""A plant counts as found when its base is this close to a true plant's."""
MIN_MATCHED_PLANTS = 4
MIN_MATCHED_FRACTION = 0.6
KINECT_DEPTH_SHAPE = (424, 512)


class SmokeFailure(Exception):
    """A step of the smoke test failed; ``step`` names it."""

    def __init__(self, step: str, message: str) -> None:
        super().__init__(f"{step}: {message}")
        self.step = step


@dataclass(frozen=True)
class PlantCheck:
    """Plants the reconstruction found, how many sit on a true plant, and how many exist."""

    found: int
    matched: int
    truth: int

    def problem(self) -> str | None:
        """Why this is not a working reconstruction, or ``None``."""
        if self.found == 0:
            return "the reconstruction found no plant"
        if self.matched < MIN_MATCHED_PLANTS or self.matched < MIN_MATCHED_FRACTION * self.found:
            return (
                f"only {self.matched} of {self.found} plants found lie within "
                f"{MATCH_DISTANCE_M:.2f} m of a true plant (need >= {MIN_MATCHED_PLANTS} "
                f"and >= {MIN_MATCHED_FRACTION:.0%})"
            )
        return None


@dataclass
class SmokeReport:
    """What the smoke test saw; ``durations_s`` per step."""

    devices: dict[str, str] = field(default_factory=dict)
    plants: PlantCheck | None = None
    durations_s: dict[str, float] = field(default_factory=dict)

    def summary(self) -> str:
        plants = self.plants
        found = f"{plants.matched}/{plants.found} plants on the truth" if plants else "no plants"
        steps = ", ".join(f"{name} {s:.1f} s" for name, s in self.durations_s.items())
        return f"window shown, devices {self.devices}, {found}; {steps}"


# --- the core part (no Qt): simulate, reconstruct, compare with the truth -------------------


def simulate_session(folder: Path, stations: Sequence[int], views: Sequence[int]) -> Path:
    """Write a simulated session of the default plot with its ``truth.json``; returns it."""
    from devices.sim.rig import RigGeometry
    from devices.sim.scene import plot_scene
    from devices.sim.world import SimWorld
    from fieldapp.cli.simulate import write_session

    world = SimWorld(plot_scene(SEED, 0), RigGeometry(), seed=SEED)
    about = {"scene": "plot", "seed": SEED, "day": 0}
    write_session(folder, world, list(stations), list(views), SEED, about)
    return folder


def check_plants(session_folder: Path, plants_xy_m: Sequence[tuple[float, float]]) -> PlantCheck:
    """Compare plant positions (field frame, metres) with the session's ``truth.json``."""
    import numpy as np

    from fieldapp.evaluate.references import load_truth
    from fieldapp.results.identity import match_positions

    truth = load_truth(session_folder / "truth.json").plants
    truth_xy_m = np.array([t.plot_xy_m for t in truth], np.float64).reshape(-1, 2)
    found_xy_m = np.array(plants_xy_m, np.float64).reshape(-1, 2)
    matches = match_positions(truth_xy_m, found_xy_m, MATCH_DISTANCE_M)
    matched = sum(match is not None for match in matches)
    return PlantCheck(found=len(found_xy_m), matched=matched, truth=len(truth))


def reconstruct_and_check(
    folder: Path, stations: Sequence[int] = STATIONS, views: Sequence[int] = VIEWS
) -> PlantCheck:
    """Simulate into ``folder``, reconstruct through the core, check against the truth."""
    from fieldapp.io.session import load_session
    from fieldapp.recon.pipeline import run_reconstruction
    from fieldapp.recon.settings import ReconstructionSettings

    simulate_session(folder, stations, views)
    result = run_reconstruction(load_session(folder), ReconstructionSettings())
    return check_plants(folder, [(p.traits.x_m, p.traits.y_m) for p in result.plants])


class Background(Generic[T]):
    """``work()`` on a daemon thread (a hung step cannot keep the process alive)."""

    def __init__(self, name: str, work: Callable[[], T]) -> None:
        self._work = work
        self.value: T | None = None
        self.error: BaseException | None = None
        self.elapsed_s = 0.0
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        started_s = time.monotonic()
        try:
            self.value = self._work()
        except BaseException as error:  # reported on the GUI thread
            self.error = error
        finally:
            self.elapsed_s = time.monotonic() - started_s

    @property
    def done(self) -> bool:
        return not self._thread.is_alive()


# --- the GUI part ------------------------------------------------------------------------------


def _process_events_until(condition: Callable[[], bool], deadline_s: float) -> bool:
    """Process Qt events until ``condition()`` holds or the monotonic deadline passes."""
    from ui.workers import process_events_until

    return process_events_until(condition, max(deadline_s - time.monotonic(), 0.0))


class Watchdog:
    """Ends the process with exit code 1 when the smoke test overruns ``timeout_s``, even if
    the GUI thread is stuck (a modal dialog, a hung driver)."""

    def __init__(self, timeout_s: float) -> None:
        self.step = "start-up"
        self._timer = threading.Timer(timeout_s, self._expire, args=(timeout_s,))
        self._timer.daemon = True

    def __enter__(self) -> Watchdog:
        self._timer.start()
        return self

    def __exit__(self, *_exc: object) -> None:
        self._timer.cancel()

    def _expire(self, timeout_s: float) -> None:
        log.error("smoke test FAILED: not done within %.1f s (step: %s)", timeout_s, self.step)
        logging.shutdown()
        os._exit(1)


@dataclass
class _Run:
    """One smoke run's state: its deadline, the step running, the durations so far."""

    deadline_s: float
    watchdog: Watchdog
    report: SmokeReport = field(default_factory=SmokeReport)
    _started_s: float = field(default_factory=time.monotonic)

    def step(self, name: str) -> None:
        """End the running step (its duration is recorded) and start ``name``."""
        now = time.monotonic()
        self.report.durations_s[self.watchdog.step] = now - self._started_s
        self.watchdog.step, self._started_s = name, now

    def wait(self, condition: Callable[[], bool], what: str) -> None:
        if not _process_events_until(condition, self.deadline_s):
            raise SmokeFailure(self.watchdog.step, f"{what} did not happen in time")


def _check_window_rendered(window: MainWindow) -> None:
    if not window.isVisible() or window.windowHandle() is None:
        raise SmokeFailure("window", "the main window is not shown")
    picture = window.grab()
    if picture.isNull() or picture.width() < 200 or picture.height() < 200:
        raise SmokeFailure("window", f"the window rendered as {picture.width()}x{picture.height()}")


def _check_devices(window: MainWindow, run: _Run) -> None:
    from ui.devices.hub import DeviceState

    hub = window.context.hub
    failed: list[BaseException] = []
    hub.connect_failed.connect(failed.append)
    hub.connect_devices(window.context.settings.devices)
    run.wait(lambda: hub.connected or bool(failed), "connecting the simulated devices")
    if failed:
        raise SmokeFailure("devices", f"the simulated devices did not open: {failed[0]}")
    run.report.devices = {name: status.state.value for name, status in hub.states.items()}
    if any(s.state is not DeviceState.SIMULATED for s in hub.states.values()):
        raise SmokeFailure("devices", f"expected every device simulated: {run.report.devices}")
    run.wait(lambda: hub.stream is not None and hub.stream.latest() is not None, "a depth frame")
    frame = hub.stream.latest() if hub.stream is not None else None
    if frame is None or frame.depth_m.shape != KINECT_DEPTH_SHAPE:
        shape = None if frame is None else frame.depth_m.shape
        raise SmokeFailure("devices", f"depth frame of shape {shape}, not {KINECT_DEPTH_SHAPE}")


def _error_notices(window: MainWindow) -> list[str]:
    from ui.notifications import Level

    history = window.context.notifier.history
    return [f"{n.title}: {n.message}" for n in history if n.level is Level.ERROR]


def _open_window(folder: Path) -> MainWindow:
    from fieldapp.settings import Settings
    from ui.app import build_window
    from ui.state import UiState

    settings = Settings()  # every device simulated, whatever the user configured
    settings.devices.realtime_simulation = False
    settings.paths.sessions_dir = folder / "sessions"
    settings.paths.results_db = folder / "results.sqlite"
    window = build_window(
        settings, settings_path=folder / "settings.yaml", ui_state=UiState(folder / "ui.ini")
    )
    window.show()
    return window


def _close_window(window: MainWindow) -> None:
    closed = window.close()
    window.deleteLater()
    _process_events_until(lambda: False, time.monotonic() + 0.1)
    if not closed:
        raise SmokeFailure("close", "the main window refused to close")


def _import_before_threads() -> None:
    """Import on this (the main) thread the modules both threads would otherwise import at
    once. Python breaks an import cycle between two threads by handing one of them a partially
    initialised module: pydantic's internals have such cycles, and the worker defining the
    session and reconstruction models while the window defines the settings' failed the smoke
    test now and then (``cannot import name 'import_string' from partially initialized module
    'pydantic._internal._validators'``)."""
    import importlib

    for name in (
        "fieldapp.settings",
        "fieldapp.io.session",
        "fieldapp.recon.settings",
        "fieldapp.recon.pipeline",
        "fieldapp.cli.simulate",
        "fieldapp.evaluate.references",
        "fieldapp.results.identity",
        "devices.sim.world",
        "devices.sim.scene",
        "devices.sim.rig",
    ):
        importlib.import_module(name)


def run_smoke_test(folder: Path, run: _Run) -> SmokeReport:
    """The steps of the module docstring in ``folder``; raises :class:`SmokeFailure`."""
    _import_before_threads()
    recon = Background("smoke-reconstruction", lambda: reconstruct_and_check(folder / "session"))
    run.step("window")
    window = _open_window(folder)
    try:
        run.wait(window.isVisible, "showing the window")
        _check_window_rendered(window)
        run.step("devices")
        _check_devices(window, run)
        run.step("reconstruction")
        run.wait(lambda: recon.done, "the simulated reconstruction")
        run.report.durations_s["simulate + reconstruct (worker)"] = recon.elapsed_s
        if recon.error is not None:
            raise SmokeFailure("reconstruction", f"{type(recon.error).__name__}: {recon.error}")
        assert recon.value is not None
        run.report.plants = recon.value
        problem = recon.value.problem()
        if problem is not None:
            raise SmokeFailure("reconstruction", problem)
        errors = _error_notices(window)
        if errors:
            raise SmokeFailure("window", f"the window reported errors: {'; '.join(errors)}")
    finally:
        run.step("close")
        _close_window(window)
    run.step("done")
    return run.report


def _qt_application() -> QtWidgets.QApplication:
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from PySide6 import QtWidgets

    app = QtWidgets.QApplication.instance()
    if not isinstance(app, QtWidgets.QApplication):
        app = QtWidgets.QApplication(["fieldapp-smoke-test"])
    app.setApplicationName("fieldapp")
    return app


def parse_arguments(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="fieldapp --smoke-test",
        description="Self-test: the main window on simulated devices (offscreen) and a tiny "
        "simulated reconstruction checked against its ground truth. Exit 0 when it passed.",
    )
    parser.add_argument("--timeout-s", type=float, default=DEFAULT_TIMEOUT_S, help="time bound")
    parser.add_argument("--keep", type=Path, help="work in this folder and keep it")
    args = parser.parse_args(argv)
    if not args.timeout_s > 0:
        parser.error(f"--timeout-s: {args.timeout_s} is not a positive number of seconds")
    return args


class _ExpectedWarnings(logging.Filter):
    """Drops the reconstruction's "captures missing" warning: the tiny session is partial on
    purpose."""

    def filter(self, record: logging.LogRecord) -> bool:
        return "captures missing" not in record.getMessage()


def main(argv: Sequence[str] | None = None) -> int:
    """Run the smoke test; 0 when it passed, 1 (and one line saying why) when not."""
    args = parse_arguments([] if argv is None else argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    log.setLevel(logging.INFO)
    logging.getLogger("fieldapp.recon.pipeline").addFilter(_ExpectedWarnings())
    started_s = time.monotonic()
    keep = args.keep
    with Watchdog(args.timeout_s) as watchdog, tempfile.TemporaryDirectory() as temporary:
        folder = keep if keep is not None else Path(temporary)
        run = _Run(started_s + args.timeout_s, watchdog)
        try:
            _qt_application()
            report = run_smoke_test(folder, run)
        except SmokeFailure as failure:
            log.error("smoke test FAILED at %s", failure)
            return 1
        except Exception as error:  # any other failure is a failed smoke test, said in a line
            log.error(
                "smoke test FAILED at %s: %s: %s", run.watchdog.step, type(error).__name__, error
            )
            return 1
    log.info("smoke test passed in %.1f s: %s", time.monotonic() - started_s, report.summary())
    return 0


if __name__ == "__main__":
    import sys

    raise SystemExit(main(sys.argv[1:]))
