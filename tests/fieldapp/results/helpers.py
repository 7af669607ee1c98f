"""Writing reconstruction output folders (plants.csv, report.json) for the tests."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

HEADER = "plant,x_m,y_m,height_cm,width_cm,points\n"


def write_results(
    folder: Path, session_id: str, rows: list[tuple[int, float, float, float, float]]
) -> Path:
    """A results folder with ``rows`` (plant, x_m, y_m, height_cm, width_cm) and a report."""
    folder.mkdir(parents=True, exist_ok=True)
    lines = [f"{p},{x:.4f},{y:.4f},{h:.2f},{w:.2f},1000\n" for p, x, y, h, w in rows]
    (folder / "plants.csv").write_text(HEADER + "".join(lines), encoding="utf-8")
    report = {
        "format": "fieldapp-reconstruction-report/1",
        "session": session_id,
        "timings_s": {"registration": 1.5},
        "settings": {"voxel_size_m": 0.002},
        "warnings": [],
    }
    (folder / "report.json").write_text(json.dumps(report), encoding="utf-8")
    return folder


def grid_plants(seed: int) -> np.ndarray:
    """(16, 2) plant bases on the paper's 4 x 4 grid at 0.8 m, jittered by up to 4 cm."""
    rng = np.random.default_rng(seed)
    xs = (np.arange(4) - 1.5) * 0.8
    X, Y = np.meshgrid(xs, xs)
    return np.stack([X.ravel(), Y.ravel()], axis=1) + rng.uniform(-0.04, 0.04, (16, 2))
