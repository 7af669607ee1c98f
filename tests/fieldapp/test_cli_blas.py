"""Every ``fieldapp`` process runs numpy's OpenBLAS on one thread (issue 22): its threads
only busy-waited on fieldapp's (N, 3) products."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

# What OPENBLAS_NUM_THREADS says at the moment numpy is first imported (OpenBLAS reads it when
# numpy loads it), and whether importing the command loaded numpy at all.
PROBE = """
import os, sys
seen = []
class Watch:
    def find_spec(self, name, path=None, target=None):
        if name == "numpy" and not seen:
            seen.append(os.environ.get("OPENBLAS_NUM_THREADS"))
sys.meta_path.insert(0, Watch())
import fieldapp.cli
loaded = "numpy" in sys.modules
import numpy
print(seen[0], loaded)
"""


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
    assert _probe(environ) == f"{preset or '1'} False"  # set before numpy, which came later


def test_nothing_imported_before_the_setting_loads_numpy() -> None:
    """The setting only works if numpy (and its OpenBLAS) is not yet loaded when it is made."""
    probe = "import fieldapp.cli._blas, sys; print('numpy' in sys.modules)"
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "False"


def test_the_command_turns_numpys_huge_pages_off() -> None:
    """Backing each fresh large array with 2 MB pages cost system time in compaction."""
    probe = "import fieldapp.cli, numpy; print(numpy._core.multiarray._get_madvise_hugepage())"
    environ = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    done = subprocess.run(
        [sys.executable, "-c", probe], env=environ, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "False"
