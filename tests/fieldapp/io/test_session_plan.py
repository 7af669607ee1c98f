"""The session's plan (session-format spec): stations' map poses and the planting grid."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fieldapp.errors import FormatError
from fieldapp.io.session import load_session
from fieldapp.mission.plan import MissionPlan, default_plan

GRID = {
    "rows": 4,
    "columns": 4,
    "row_spacing_m": 0.8,
    "plant_spacing_m": 0.8,
    "origin": {"x": 0.4, "y": 0.4},
    "row_direction_deg": 0.0,
}


def test_a_session_plan_with_a_planting_grid_is_read_and_bad_fields_are_named(
    make_spec_session, tmp_path: Path
) -> None:
    folder = make_spec_session()
    document = json.loads((folder / "session.json").read_text())
    document["plan"] = default_plan().session_plan() | {"planting_grid": dict(GRID)}
    (folder / "session.json").write_text(json.dumps(document))
    session = load_session(folder)
    assert session.document.plan is not None
    grid = session.document.plan.planting_grid
    assert grid is not None and grid.expected_plants == 16
    assert [s.number for s in session.document.plan.stations][:3] == [1, 2, 3]
    document["plan"]["planting_grid"]["rows"] = 0
    (folder / "session.json").write_text(json.dumps(document))
    with pytest.raises(FormatError, match=r"plan\.planting_grid\.rows"):
        load_session(folder)


def test_the_mission_plan_carries_the_grid_into_the_session_plan() -> None:
    plan = MissionPlan.model_validate(default_plan().model_dump() | {"planting_grid": GRID})
    document = plan.session_plan()
    assert document["planting_grid"]["origin"] == {"x": 0.4, "y": 0.4}
    assert [s["number"] for s in document["stations"]] == [1, 2, 3, 6, 5, 4, 7, 8, 9]
    assert "planting_grid" not in default_plan().session_plan()


@pytest.mark.parametrize(
    "stations",
    [
        [{"id": 1, "map_pose": {"x": 0.5, "y": -1.0, "yaw_deg": 90.0}}],  # nested pose
        {"1": {"x": 0.5, "y": -1.0, "yaw_deg": 90.0}},  # keyed by station number
        [{"station": 1, "x": 0.5, "y": -1.0, "yaw_deg": 90.0}],  # the base pose's names
    ],
)
def test_plan_stations_in_the_common_shapes_are_read(make_spec_session, stations) -> None:
    """The spec names no fields for the plan's stations; another tool's common shapes are read."""
    folder = make_spec_session()
    document = json.loads((folder / "session.json").read_text())
    document["plan"] = {"stations": stations, "planting_grid": dict(GRID)}
    (folder / "session.json").write_text(json.dumps(document))
    plan = load_session(folder).document.plan
    assert plan is not None
    assert [(s.number, s.x_m, s.y_m, s.yaw_deg) for s in plan.stations] == [(1, 0.5, -1.0, 90.0)]


def test_a_plan_whose_stations_cannot_be_read_is_left_out_not_the_session(
    make_spec_session, caplog: pytest.LogCaptureFixture
) -> None:
    """The plan only informs a reconstruction: stations in a shape no reader could guess are
    left out with a warning naming the field; the session and its grid are read."""
    folder = make_spec_session()
    document = json.loads((folder / "session.json").read_text())
    document["plan"] = {"stations": [{"where": "north"}], "planting_grid": dict(GRID)}
    (folder / "session.json").write_text(json.dumps(document))
    session = load_session(folder)
    assert session.document.plan is not None
    assert session.document.plan.stations == []
    assert session.document.plan.planting_grid is not None
    assert "plan.stations not read (stations.0.number" in caplog.text
