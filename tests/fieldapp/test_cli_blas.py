"""Every ``fieldapp`` process runs numpy's OpenBLAS on one thread (issue 22): its threads
only busy-waited on fieldapp's (N, 3) products."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

PROBE = (
    "import fieldapp.cli, os, numpy; "
    "print(os.environ['OPENBLAS_NUM_THREADS'], 'numpy' in __import__('sys').modules)"
)


def _probe(environ: dict[str, str]) -> str:
    done = subprocess.run(
        [sys.executable, "-c", PROBE], env=environ, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


@pytest.mark.parametrize("preset", [None, "2"])
def test_the_command_sets_openblas_to_one_thread_unless_told_otherwise(
    preset: str | None,
) -> None:
    environ = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if preset is not None:
        environ["OPENBLAS_NUM_THREADS"] = preset
    assert _probe(environ) == f"{preset or '1'} True"


def test_nothing_imported_before_the_setting_loads_numpy() -> None:
    """The setting only works if numpy (and its OpenBLAS) is not yet loaded when it is made."""
    probe = "import fieldapp.cli._blas, sys; print('numpy' in sys.modules)"
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "False"
