"""``fieldapp mission``: plan, run, resume from the command line; bad input is one line."""

from __future__ import annotations

from pathlib import Path

import pytest

from fieldapp.cli import main
from fieldapp.io.session import load_session
from fieldapp.mission.plan import load_plan, save_plan

from .conftest import small_plan


def test_plan_writes_the_default_plan_for_editing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["mission", "plan", "--out", str(tmp_path / "plan.yaml")]) == 0
    plan = load_plan(tmp_path / "plan.yaml")
    assert len(plan.capture_keys()) == 72 and plan.station_numbers()[:4] == [1, 2, 3, 6]
    assert "9 stations x 8 views" in capsys.readouterr().out


def test_run_then_resume_of_a_complete_session(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plan_path = save_plan(small_plan(stations=(5,), views=2), tmp_path / "plan.yaml")
    out = tmp_path / "S"
    assert (
        main(["mission", "run", "--plan", str(plan_path), "--sim", "--fast", "--out", str(out)])
        == 0
    )
    captured = capsys.readouterr()
    assert "complete (2 captures)" in captured.out
    assert "s05 v1 at" in captured.err and "camera: simulated" in captured.err
    assert main(["mission", "resume", str(out), "--fast"]) == 0
    assert "0 of 2 captures to take" in capsys.readouterr().err
    assert len(load_session(out).captures) == 2
    assert main(["verify", str(out)]) == 0


def test_run_checks_the_battery_levels_of_the_settings(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("FIELDAPP_BATTERY__WARN_PCT", "100")
    monkeypatch.setenv("FIELDAPP_BATTERY__CRITICAL_PCT", "100")  # even a full battery is low
    plan_path = save_plan(small_plan(stations=(5,), views=1), tmp_path / "plan.yaml")
    out = tmp_path / "S"
    argv = ["mission", "run", "--plan", str(plan_path), "--sim", "--fast", "--out", str(out)]
    assert main(argv) != 0
    captured = capsys.readouterr()
    assert "incomplete" in captured.out and "battery" in captured.err.lower()
    assert not list(out.rglob("*.png"))  # nothing was captured


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["mission", "run", "--plan", "{tmp}/nope.yaml", "--out", "{tmp}/S"],
            "plan file is missing",
        ),
        (["mission", "resume", "{tmp}"], "not a mission folder"),
        (["mission", "run", "--plan", "{tmp}/bad.yaml", "--out", "{tmp}/S"], "frames_per_capture"),
    ],
)
def test_bad_input_is_one_line_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    (tmp_path / "bad.yaml").write_text(
        "stations: [{number: 5, x_m: 0, y_m: 0}]\nframes_per_capture: -1\n"
    )
    assert main([a.format(tmp=tmp_path) for a in argv]) == 1
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_run_refuses_a_folder_that_holds_a_session(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plan_path = save_plan(small_plan(stations=(5,), views=1), tmp_path / "plan.yaml")
    argv = ["mission", "run", "--plan", str(plan_path), "--fast", "--out", str(tmp_path / "S")]
    assert main(argv) == 0
    capsys.readouterr()
    assert main(argv) == 1
    assert "already holds a session; resume it" in capsys.readouterr().err
