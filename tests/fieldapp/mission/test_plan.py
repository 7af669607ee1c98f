"""The plan: the paper's default, files in and out, bad files named field by field."""

from __future__ import annotations

from itertools import pairwise
from pathlib import Path

import pytest

from fieldapp.errors import FormatError
from fieldapp.mission.execute import visits
from fieldapp.mission.plan import default_plan, load_plan, save_plan

from .conftest import small_plan


def test_default_plan_is_the_papers_grid_in_serpentine_order() -> None:
    plan = default_plan()
    assert plan.station_numbers() == [1, 2, 3, 6, 5, 4, 7, 8, 9]
    assert plan.reference_station == 5
    centre = plan.station(5)
    assert (centre.x_m, centre.y_m) == pytest.approx((1.6, 1.6))  # the base protocol's example
    corner = plan.station(9)
    assert (corner.x_m, corner.y_m) == pytest.approx((3.2, 3.2))
    assert [plan.views.angle_deg(v) for v in range(plan.views.count)] == [
        0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0
    ]  # fmt: skip
    keys = plan.capture_keys()
    assert len(keys) == 72 and len(set(keys)) == 72
    steps = [abs(a.x_m - b.x_m) + abs(a.y_m - b.y_m) for a, b in pairwise(plan.stations)]
    assert steps == pytest.approx([1.6] * 8)  # serpentine: every move is one grid step


@pytest.mark.parametrize("name", ["plan.yaml", "plan.json"])
def test_plan_files_round_trip(tmp_path: Path, name: str) -> None:
    plan = small_plan(settle_s=1.25, keep_low_quality=True)
    loaded = load_plan(save_plan(plan, tmp_path / name))
    assert loaded == plan


@pytest.mark.parametrize(
    ("text", "field", "message"),
    [
        ("stations: []\n", "stations", "at least 1"),
        ("stations: [{number: 1, x_m: 0, y_m: 0}]\nreference_station: 5\n", "(document)",
         "reference station 5 is not in the plan"),
        ("stations: [{number: 1, x_m: 0, y_m: 0}, {number: 1, x_m: 1, y_m: 0}]\n"
         "reference_station: 1\n", "stations", "repeat"),
        ("stations: [{number: 5, x_m: .nan, y_m: 0}]\n", "stations[0].x_m", "finite"),
        ("stations: [{number: 5, x_m: 0, y_m: 0}]\nviews: {count: 9, step_deg: 45}\n", "views",
         "overlap a turn"),
        ("stations: [{number: 5, x_m: 0, y_m: 0}]\nframes_per_capture: 0\n",
         "frames_per_capture", "greater than or equal to 1"),
        ("stations: [{number: 5, x_m: 0, y_m: 0}]\nsetle_s: 1\n", "setle_s", "not permitted"),
    ],
)  # fmt: skip
def test_a_bad_plan_names_its_file_and_field(
    tmp_path: Path, text: str, field: str, message: str
) -> None:
    path = tmp_path / "plan.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(FormatError) as caught:
        load_plan(path)
    problems = caught.value.problems
    assert any(
        p.file == str(path) and p.field == field and message in p.message for p in problems
    ), problems


@pytest.mark.parametrize(
    ("text", "message"),
    [("- just\n- a list\n", "mapping"), ("stations: [\n", "malformed"), (None, "missing")],
)
def test_an_unreadable_plan_is_a_format_error(
    tmp_path: Path, text: str | None, message: str
) -> None:
    path = tmp_path / "plan.yaml"
    if text is not None:
        path.write_text(text, encoding="utf-8")
    with pytest.raises(FormatError, match=message):
        load_plan(path)


def test_visits_keep_plan_order_and_alternate_the_views() -> None:
    plan = small_plan(stations=(1, 2, 3), views=3)
    todo = [(1, 0), (1, 2), (2, 0), (2, 1), (2, 2), (3, 1)]
    order = [(station.number, views) for station, views in visits(plan, list(reversed(todo)))]
    assert order == [(1, [0, 2]), (2, [2, 1, 0]), (3, [1])]
    plan.views.alternate = False
    assert [views for _, views in visits(plan, todo)][1] == [0, 1, 2]
