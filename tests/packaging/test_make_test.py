"""`make test` runs the suite on pytest-xdist workers: a worker that crashes (a segfault in a
binding) must end the run red, naming the test, not hang it. pytest-xdist 3.8 replaces a
crashed worker by default, and under ``--dist loadfile`` the run can then wait forever on the
replacement (pytest-xdist #784, #1323); CI saw exactly that, killed at its 90-minute limit."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

MAKEFILE = Path(__file__).resolve().parents[2] / "Makefile"
PYPROJECT = MAKEFILE.with_name("pyproject.toml")
HANG_S = 240.0  # a hang detector only (under pytest-timeout's 300 s): the toy suite takes seconds


def make_test_xdist_options(workers: int) -> list[str]:
    """The worker options the Makefile's ``test`` target gives pytest."""
    text = MAKEFILE.read_text()
    match = re.search(r"^XDIST\s*:=\s*(.+)$", text, re.MULTILINE)
    assert match, "Makefile: no XDIST := line"
    recipe = text.split("\ntest:", 1)[1].split("\n\n", 1)[0]
    assert "$(XDIST)" in recipe, "the test target does not pass XDIST to pytest"
    return match.group(1).replace("$(TEST_WORKERS)", str(workers)).split()


def run_like_make_test(folder: Path, *options: str) -> tuple[int, str]:
    """pytest over the toy suite in ``folder`` with the Makefile's worker options (and
    ``options``): its exit code and output."""
    command = [sys.executable, "-m", "pytest", *make_test_xdist_options(2), *options]
    command += ["-p", "no:cacheprovider", "-p", "no:dash", "-o", "addopts=", "-q"]
    run = subprocess.run(
        command, cwd=folder, capture_output=True, text=True, timeout=HANG_S, check=False
    )
    return run.returncode, run.stdout + run.stderr


def test_a_crashing_worker_ends_the_run_and_names_its_test(tmp_path: Path) -> None:
    for name in ("test_a.py", "test_c.py", "test_d.py"):
        (tmp_path / name).write_text("def test_one():\n    pass\n\ndef test_two():\n    pass\n")
    (tmp_path / "test_b.py").write_text(
        textwrap.dedent(
            """
            import ctypes

            def test_before():
                pass

            def test_crash():
                ctypes.string_at(0)  # a segfault, as a binding's would be

            def test_after():
                pass
            """
        )
    )
    code, out = run_like_make_test(tmp_path)
    assert code != 0, out
    assert "crashed while running 'test_b.py::test_crash'" in out, out
    assert "replacing crashed worker" not in out, out


def test_a_test_stuck_in_c_code_ends_the_run_and_names_itself(tmp_path: Path) -> None:
    """A test blocked inside C code (a Qt wait here) never returns to the interpreter, so
    pytest-timeout's signal method would wait with it, and the run with it; the project's
    method (``timeout_method`` in pyproject.toml) ends it: the worker is ended (its stacks go
    to its own stderr), and the run with it, naming the test."""
    (tmp_path / "test_a.py").write_text("def test_one():\n    pass\n")
    (tmp_path / "test_stuck.py").write_text(
        textwrap.dedent(
            """
            from PySide6 import QtCore

            def test_stuck():
                QtCore.QThread.sleep(3600)  # retried on EINTR: no signal handler ever runs
            """
        )
    )
    options = tomllib.loads(PYPROJECT.read_text())["tool"]["pytest"]["ini_options"]
    method = f"timeout_method={options['timeout_method']}"
    code, out = run_like_make_test(tmp_path, "-o", "timeout=2", "-o", method)
    assert code != 0, out
    assert "crashed while running 'test_stuck.py::test_stuck'" in out, out
