"""What ``fieldapp reconstruct`` loads before it works (issue 22: start-up)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

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
