"""Fixtures shared by every test folder."""

from __future__ import annotations

import fcntl
import gc
import logging
import os
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def under_ci() -> bool:
    """``CI=true`` in the environment: missing test data is then a failure, not a skip."""
    return os.environ.get("CI", "").strip().lower() == "true"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` beside the repository (``FIELDAPP_SHARED_DATA`` overrides it).

    Tests that need it skip with a one-line reason when it is absent, except under CI, where
    they fail: CI must run them.
    """
    folder = Path(os.environ.get("FIELDAPP_SHARED_DATA", REPO.parent / "shared" / "data"))
    if not folder.is_dir():
        message = f"shared test data not found at {folder} (set FIELDAPP_SHARED_DATA)"
        if under_ci():
            pytest.fail(f"{message}; CI=true requires it")
        pytest.skip(message)
    return folder


def pytest_collection_finish(session: pytest.Session) -> None:
    """Every test module is imported now, and with them numpy, Open3D, Qt and pyqtgraph: some
    200 000 objects that live as long as the process. Frozen out of the garbage collector
    (``gc.freeze``), they are no longer scanned by each collection: the UI tests' teardowns
    collect six times each (Qt's deferred deletes flushed, pyqtgraph's menus freed from their
    cycles), 122 ms a collection before and 18 ms after on two UI test files (8.1 -> 1.2 s of
    their 25 s). What the tests create is collected as before."""
    gc.collect()
    gc.freeze()


_OURS = ("fieldapp", "devices", "ui")


@pytest.fixture(autouse=True)
def _logger_levels_as_found() -> Iterator[None]:
    """A command run in process (``main([...])``) may quiet the application's loggers for its
    run (``fieldapp mission run`` sets ``devices`` to ERROR): each test leaves the levels as
    it found them, so a later test's ``caplog`` sees the warnings it checks for."""
    names = {*_OURS, *(n for n in logging.root.manager.loggerDict if n.split(".")[0] in _OURS)}
    levels = {name: logging.getLogger(name).level for name in names}
    yield
    for name, level in levels.items():
        logging.getLogger(name).setLevel(level)


OnceBuilder = Callable[[str, Callable[[Path], None]], Path]


@pytest.fixture(scope="session")
def built_once(tmp_path_factory: pytest.TempPathFactory) -> OnceBuilder:
    """``built_once(name, build)``: the folder ``name``, filled by ``build(folder)`` once per
    test run and shared by every pytest-xdist worker.

    ``make test`` spreads the files over two workers, and a session fixture is built once per
    worker: the batch tests' twelve sessions and their reconstructions (30 s) were built twice.
    The first worker to ask builds the folder under a lock in the run's temporary directory;
    the other waits for it and reads it. Fixtures that use it must only read the folder. A
    build interrupted half-way (a worker killed) is built again from scratch.
    """
    worker = os.environ.get("PYTEST_XDIST_WORKER")

    def build_once(name: str, build: Callable[[Path], None]) -> Path:
        if worker is None:  # one process: nothing to share
            folder = tmp_path_factory.mktemp(name)
            build(folder)
            return folder
        run_root = tmp_path_factory.getbasetemp().parent  # this run's, shared by its workers
        folder, done = run_root / f"once-{name}", run_root / f"once-{name}.done"
        with (run_root / f"once-{name}.lock").open("w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
            if not done.exists():
                shutil.rmtree(folder, ignore_errors=True)
                folder.mkdir()
                build(folder)
                done.touch()
        return folder

    return build_once


@pytest.fixture(scope="session")
def small_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small real-looking session to copy and damage: the simulated plot (seed 3) seen from
    stations 4 and 5, views 0 and 1, at half resolution (256 x 212), written by
    :class:`SessionWriter` (so with checksums). Reconstructs in about 0.1 s of CPU."""
    from fieldapp.cli import main
    from fieldapp.io.session import load_session
    from fieldapp.io.writer import SessionWriter

    root = tmp_path_factory.mktemp("small-session")
    args = ["--stations", "4,5", "--views", "0,1", "--seed", "3"]
    assert main(["simulate", "--out", str(root / "full"), *args]) == 0
    full = load_session(root / "full")
    camera = full.calibration.depth_camera
    half = camera.model_copy(
        update={
            "width": camera.width // 2,
            "height": camera.height // 2,
            **{k: getattr(camera, k) / 2 for k in ("fx", "fy", "cx", "cy")},
        }
    )
    calibration = full.calibration.model_copy(update={"depth_camera": half})
    writer = SessionWriter.create(root / "half", f"{full.id}-half", calibration)
    for capture in full.captures:
        images = full.read_capture(capture, with_ir=True)
        assert images.ir is not None
        writer.add_capture(
            capture.station,
            capture.view,
            images.depth_m[::2, ::2],
            images.color[::2, ::2],
            ir=images.ir[::2, ::2],
            angle_deg=capture.angle_deg,
            base_pose=capture.base_pose,
        )
    return root / "half"


SimulateRefuses = Callable[[str, list[tuple[str, str]]], None]


@pytest.fixture
def simulate_refuses(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> SimulateRefuses:
    """``simulate_refuses(option, [(bad value, message), ...])``: ``fieldapp simulate`` with
    each bad value of ``option`` exits 1, says the message and writes no session."""
    from fieldapp.cli import main

    def check(option: str, cases: list[tuple[str, str]]) -> None:
        out = tmp_path / "refused"
        for bad, message in cases:
            assert main(["simulate", "--out", str(out), option, bad]) == 1
            assert message in capsys.readouterr().err
            assert not out.exists()

    return check
