"""Fast start: ``fieldapp gui`` shows its first window without loading Open3D, SciPy,
matplotlib, Dask or OpenCV (they load when first used). Checked on the real command in a fresh
process through the start-up probe; no duration is asserted (``benchmarks/bench_startup.py``
measures it)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

HANG_S = 300.0


def test_the_first_window_loads_no_heavy_module(tmp_path: Path) -> None:
    probe = tmp_path / "probe.json"
    env = dict(os.environ)
    env.update(
        FIELDAPP_STARTUP_PROBE=str(probe),
        XDG_CONFIG_HOME=str(tmp_path / "config"),
        XDG_DATA_HOME=str(tmp_path / "data"),
        QT_QPA_PLATFORM="offscreen",
    )
    command = [sys.executable, "-m", "fieldapp", "gui", "--settings", str(tmp_path / "s.yaml")]
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=HANG_S)
    assert done.returncode == 0, done.stderr[-2000:]
    shown = json.loads(probe.read_text())
    assert shown["heavy_modules"] == [], shown
