"""What ``fieldapp reconstruct`` loads before it works (issue 22: start-up)."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

QUIET_RUN = textwrap.dedent(
    """
    import sys
    from fieldapp.cli.reconstruct import _run_with_bar
    from fieldapp.recon.progress import progress

    def steps():
        yield progress("levelling", 0.5, "half")
        yield progress("levelling", 1.0, "done")
        return "result"

    assert _run_with_bar(steps(), quiet=True) == "result"
    print(sorted(m for m in sys.modules if m.partition(".")[0] == "rich"))
    """
)


def test_a_quiet_reconstruction_runs_to_its_end_without_loading_the_progress_bar() -> None:
    done = subprocess.run(
        [sys.executable, "-c", QUIET_RUN], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


EARLY_READER = textwrap.dedent(
    """
    import sys
    from fieldapp.cli import main
    from fieldapp.recon import early

    started = []
    start = early.start_reading

    def watched(session, settings):
        heavy = ("scipy", "small_gicp", "open3d", "fieldapp.recon.pipeline")
        started.append(sorted(m for m in heavy if m in sys.modules))
        return start(session, settings)

    early.start_reading = watched
    code = main(["reconstruct", sys.argv[1], "--out", sys.argv[2], "--quiet"])
    print(code, started)
    """
)


def test_the_stations_reader_starts_before_scipy_and_small_gicp_load(
    small_session: Path, tmp_path: Path
) -> None:
    """The reader forked at start-up overlaps the imports only if it starts before them."""
    assert _last_line(EARLY_READER, small_session, tmp_path / "out") == "0 [[]]"
    assert (tmp_path / "out" / "plants.csv").is_file()


def _last_line(script: str, session: Path, out: Path) -> str:
    """The last line ``script`` prints, run in a fresh interpreter on ``session`` and ``out``."""
    done = subprocess.run(
        [sys.executable, "-c", script, str(session), str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout.strip().splitlines()[-1]


FROZEN_AT_EXIT = textwrap.dedent(
    """
    import atexit, gc, sys
    start = gc.get_freeze_count()  # 0; from Python 3.12 the interpreter's own few hundred
    from fieldapp.cli import main

    code = main(["reconstruct", sys.argv[1], "--out", sys.argv[2], "--quiet"])
    before = gc.get_freeze_count()
    atexit._run_exitfuncs()  # what the interpreter's exit runs first
    print(code, before - start, gc.get_freeze_count() > before)
    """
)


def test_the_objects_are_frozen_only_when_the_process_exits(
    small_session: Path, tmp_path: Path
) -> None:
    """The exit's last collection skips the imports' objects (0.1 s of a run); a caller that
    runs the command in its own process keeps collecting until it exits."""
    assert _last_line(FROZEN_AT_EXIT, small_session, tmp_path / "out") == "0 0 True"
