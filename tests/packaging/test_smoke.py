"""ui/smoke.py: the verdict on the plants against the truth, and the whole smoke test run as
the bundle runs it (a process on the offscreen platform): it passes, and a time bound too
short for it fails with one line naming the step."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from fieldapp.errors import FieldappError
from ui.smoke import MATCH_DISTANCE_M, PlantCheck, check_plants, parse_arguments

REPO = Path(__file__).resolve().parents[2]


def write_truth(folder: Path, plants_xy_m: list[tuple[float, float]]) -> Path:
    plants = [
        {"name": f"p{i}", "x_m": x, "y_m": y, "height_cm": 30.0, "width_cm": 40.0}
        for i, (x, y) in enumerate(plants_xy_m)
    ]
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "truth.json").write_text(
        json.dumps({"format": "fieldapp-sim-truth/1", "plants": plants})
    )
    return folder


GRID = [(x * 0.8, y * 0.8) for x in range(3) for y in range(3)]


def test_plants_on_the_truth_pass(tmp_path: Path) -> None:
    session = write_truth(tmp_path, GRID)
    near = [(x + 0.05, y - 0.03) for x, y in GRID[:6]] + [(5.0, 5.0)]
    check = check_plants(session, near)
    assert check == PlantCheck(found=7, matched=6, truth=9)
    assert check.problem() is None


def test_plants_off_the_truth_fail(tmp_path: Path) -> None:
    session = write_truth(tmp_path, GRID)
    off = [(x + MATCH_DISTANCE_M * 1.5, y) for x, y in GRID]
    check = check_plants(session, off)
    assert check.matched == 0
    assert "only 0 of 9 plants" in (check.problem() or "")


@pytest.mark.parametrize(
    ("check", "fails"),
    [
        (PlantCheck(found=0, matched=0, truth=16), "no plant"),
        (PlantCheck(found=4, matched=3, truth=16), "only 3 of 4"),  # too few
        (PlantCheck(found=12, matched=6, truth=16), "only 6 of 12"),  # too many strays
        (PlantCheck(found=8, matched=7, truth=16), None),
    ],
)
def test_verdict(check: PlantCheck, fails: str | None) -> None:
    problem = check.problem()
    assert (problem is None) if fails is None else (fails in (problem or ""))


def test_a_missing_truth_is_a_typed_error(tmp_path: Path) -> None:
    with pytest.raises(FieldappError):
        check_plants(tmp_path, [(0.0, 0.0)])


def test_timeout_must_be_positive() -> None:
    assert parse_arguments(["--timeout-s", "30"]).timeout_s == 30.0
    with pytest.raises(SystemExit):
        parse_arguments(["--timeout-s", "0"])


def smoke(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """The smoke test in a process, with ``cwd/home`` as the user's home."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("FIELDAPP_", "XDG_"))}
    env["HOME"] = str(cwd / "home")
    env.pop("DISPLAY", None)
    env.pop("QT_QPA_PLATFORM", None)  # the smoke test chooses offscreen itself
    return subprocess.run(
        [sys.executable, str(REPO / "packaging" / "entry.py"), "--smoke-test", *args],
        capture_output=True,
        text=True,
        timeout=110,
        env=env,
        cwd=cwd,
    )


@pytest.mark.slow
def test_smoke_test_passes_headless(tmp_path: Path) -> None:
    done = smoke("--timeout-s", "90", "--keep", str(tmp_path / "work"), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "smoke test passed" in done.stderr
    assert "'camera': 'simulated'" in done.stderr
    truth = json.loads((tmp_path / "work/session/truth.json").read_text())
    assert len(truth["plants"]) == 16
    assert (tmp_path / "work/session/session.json").is_file()
    assert (tmp_path / "work/ui.ini").is_file()  # the window's state went to the work folder
    written = [p for p in (tmp_path / "home").rglob("*") if "fieldapp" in str(p)]
    assert written == []  # no settings, window state, sessions or results of the user's


def test_a_time_bound_too_short_fails_with_the_step(tmp_path: Path) -> None:
    done = smoke("--timeout-s", "0.3", cwd=tmp_path)
    assert done.returncode == 1
    lines = [line for line in done.stderr.splitlines() if "FAILED" in line]
    assert len(lines) == 1, done.stderr
    assert "not done within 0.3 s (step: " in lines[0]
