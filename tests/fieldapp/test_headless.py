"""The core and the CLI installed without the GUI packages (the "gui" extra), as a batch
worker or cluster node runs them: every non-GUI command works, and ``fieldapp gui`` says in one
line what to install. The Qt packages are hidden from a child interpreter by an import hook."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

HIDE_QT = textwrap.dedent(
    """
    import importlib.abc, sys

    class NoQt(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.partition(".")[0] in {"PySide6", "shiboken6", "pyqtgraph", "superqt",
                                          "OpenGL", "qtpy"}:
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)
            return None

    sys.meta_path.insert(0, NoQt())
    from fieldapp.cli import main
    code = main(sys.argv[1:])
    loaded = sorted(m for m in sys.modules if m.partition(".")[0] in {"PySide6", "pyqtgraph"})
    print("qt modules loaded:", loaded)
    sys.exit(code)
    """
)


def _fieldapp_without_qt(*argv: str) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("FIELDAPP_")}
    env["FIELDAPP_SETTINGS"] = os.devnull + ".absent.yaml"
    return subprocess.run(
        [sys.executable, "-c", HIDE_QT, *argv],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )


def test_simulate_and_reconstruct_run_without_qt(tmp_path: Path) -> None:
    session, out = tmp_path / "session", tmp_path / "out"
    simulate = _fieldapp_without_qt(
        "simulate", "--out", str(session), "--stations", "5", "--views", "0-3"
    )
    assert simulate.returncode == 0, simulate.stderr
    reconstruct = _fieldapp_without_qt("reconstruct", str(session), "--out", str(out), "--quiet")
    assert reconstruct.returncode == 0, reconstruct.stderr
    assert (out / "plants.csv").is_file()
    assert "qt modules loaded: []" in reconstruct.stdout


def test_gui_without_qt_says_what_to_install() -> None:
    result = _fieldapp_without_qt("gui", "--no-connect")
    assert result.returncode == 1
    assert "pip install 'fieldapp[gui]'" in result.stderr
    assert "Traceback" not in result.stderr
