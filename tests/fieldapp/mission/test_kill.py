"""SIGKILL the mission process at random points: the folder always loads with only complete
captures listed, and resuming always ends with exactly the planned captures."""

from __future__ import annotations

import random
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from fieldapp.io.session import SESSION_FILE, load_session
from fieldapp.mission.folder import PLAN_FILE
from fieldapp.mission.plan import save_plan
from fieldapp.verify import capture_file_problems, verify_session

from .conftest import small_plan

KILLS = 8


def mission_command(folder: Path, plan: Path) -> list[str]:
    action = ["resume", str(folder)] if (folder / PLAN_FILE).exists() else [
        "run", "--plan", str(plan), "--out", str(folder)
    ]  # fmt: skip
    return [sys.executable, "-m", "fieldapp", "mission", *action, "--fast"]


def assert_consistent(folder: Path) -> int:
    """Whatever is listed is complete and decodable, and listed once; returns the count."""
    if not (folder / SESSION_FILE).exists():
        return 0
    session = load_session(folder, allow_empty=True)
    keys = [(c.station, c.view) for c in session.captures]
    assert len(keys) == len(set(keys)), keys
    for capture in session.captures:
        assert capture_file_problems(session, capture) == [], capture
    return len(keys)


@pytest.mark.slow
def test_sigkill_at_random_points_loses_nothing_and_resume_completes(tmp_path: Path) -> None:
    plan = small_plan(stations=(5, 4), views=3)
    plan_path = save_plan(plan, tmp_path / "plan.yaml")
    expected = sorted(plan.capture_keys())
    rng = random.Random(20230607)
    folders = [tmp_path / "S0"]
    kills = 0
    while kills < KILLS:
        folder = folders[-1]
        process = subprocess.Popen(
            mission_command(folder, plan_path), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        try:
            process.wait(timeout=rng.uniform(0.8, 3.2))
        except subprocess.TimeoutExpired:
            process.send_signal(signal.SIGKILL)
            process.wait()
            kills += 1
        assert_consistent(folder)
        if process.returncode == 0:  # it finished before the kill: kill the next one
            folders.append(tmp_path / f"S{len(folders)}")
    for folder in folders:
        if not (folder / PLAN_FILE).exists():
            continue
        finished = subprocess.run(mission_command(folder, plan_path), capture_output=True,
                                  text=True, timeout=90)  # fmt: skip
        assert finished.returncode == 0, finished.stderr
        report = verify_session(folder)
        assert report.usable, report.problems
        session = load_session(folder)
        assert sorted((c.station, c.view) for c in session.captures) == expected
        assert not list(folder.rglob(".*.tmp"))
