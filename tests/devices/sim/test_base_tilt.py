"""``simulate --base-tilt``: rough ground under the wheels tilts the base at each stop beyond
the soil's own slope (a wheel on a clod or in a rut: 4 cm over the 0.5 m wheelbase is 4.6
degrees), so that levelling and registration are tested on a tilted base."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fieldapp.cli import main


def _cameras(folder: Path, *options: str) -> dict[str, np.ndarray]:
    common = ["--grid", "2", "--views", "0", "--seed", "4"]
    assert main(["simulate", "--out", str(folder), *common, *options]) == 0
    truth = json.loads((folder / "truth.json").read_text())
    return {s: np.array(T) for s, T in truth["T_field_camera"].items()}


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    R = a[:3, :3] @ b[:3, :3].T
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))))


def test_the_base_tilts_by_up_to_the_asked_angle_and_the_same_again(tmp_path: Path) -> None:
    level = _cameras(tmp_path / "level")
    tilted = _cameras(tmp_path / "tilted", "--base-tilt", "5")
    again = _cameras(tmp_path / "again", "--base-tilt", "5")
    angles = [_angle_deg(tilted[s], level[s]) for s in level]  # the same stops, yaw included
    assert max(angles) > 1.0  # four stops: some wheel stands on a clod
    assert max(angles) <= np.hypot(5.0, 5.0) + 0.1  # up to 5 degrees about each axis
    for s in tilted:
        np.testing.assert_array_equal(tilted[s], again[s])  # a seed's stops tilt the same


def test_a_tilt_out_of_range_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "--out", str(tmp_path / "a"), "--base-tilt", "20"]) != 0
    assert "--base-tilt: 20 is outside 0..10 degrees" in capsys.readouterr().err
