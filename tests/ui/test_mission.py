"""Mission control on simulated devices (instant moves), driving the real widgets: connect,
start, pause, STOP, resume to the end; closing during a mission; the plan editor."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from fieldapp.io.session import load_session
from fieldapp.mission.events import MissionState, Outcome
from fieldapp.mission.plan import MissionPlan, StationPlan, ViewPlan, load_plan
from ui.main_window import MainWindow
from ui.mission.page import MissionPage
from ui.mission.plan_map import DONE

pytestmark = pytest.mark.usefixtures("no_leaks")

Wait = Callable[..., bool]


def small_plan() -> MissionPlan:
    """Three stations of the paper's grid, four views 45 degrees apart, one frame each."""
    stations = [
        StationPlan(number=5, x_m=1.6, y_m=1.6),
        StationPlan(number=6, x_m=3.2, y_m=1.6),
        StationPlan(number=3, x_m=3.2, y_m=0.0),
    ]
    return MissionPlan(
        name="small", stations=stations, views=ViewPlan(count=4), frames_per_capture=1,
        settle_s=0.0,
    )  # fmt: skip


def connected_page(
    make_window: Callable[..., MainWindow], wait_until: Wait
) -> tuple[MainWindow, MissionPage]:
    window = make_window()
    page = window.pages["mission"]
    assert isinstance(page, MissionPage)
    page.editor.set_plan(small_plan())
    assert not page.start_button.isEnabled()  # not connected yet
    window.toggle_connection()
    assert wait_until(lambda: window.context.hub.connected)
    assert page.start_button.isEnabled()
    return window, page


def test_start_pause_stop_resume_to_the_end(
    make_window: Callable[..., MainWindow], wait_until: Wait, never_within: Wait
) -> None:
    window, page = connected_page(make_window, wait_until)
    rig = window.context.hub.rig
    assert rig is not None and rig.sim_base is not None
    page.start_button.click()
    assert wait_until(lambda: page.progress.captured >= 1)
    assert page.controller.state is MissionState.RUNNING
    assert not page.start_button.isEnabled() and page.abort_button.isEnabled()

    page.pause_button.click()
    # the mission thread sets the state; the button follows once the GUI thread has the signal
    assert wait_until(lambda: page.controller.state is MissionState.PAUSED, 10.0)
    assert wait_until(lambda: page.pause_button.text().endswith("Continue"), 10.0)
    assert wait_until(lambda: "(paused)" in page.progress.times.text())
    held = page.progress.captured
    assert never_within(lambda: page.progress.captured > held, 0.6)  # nothing while paused
    page.pause_button.click()
    assert wait_until(lambda: page.controller.state is MissionState.RUNNING, 5.0)
    assert wait_until(lambda: "(paused)" not in page.progress.times.text())

    window.emergency_stop()
    assert wait_until(lambda: page.result is not None)
    assert page.result is not None and page.result.outcome is Outcome.STOPPED
    assert page.result.missing, "the mission was stopped before its end"
    assert rig.sim_base.latched  # the base obeyed STOP
    assert "stopped" in window.notices.cards()[0].label.text()
    folder = page.controller.folder
    assert folder is not None and folder.parent == window.context.settings.paths.sessions_dir
    taken_before = len(load_session(folder).captures)
    assert taken_before == page.result.captured

    page.resume(folder)
    assert wait_until(lambda: page.result is not None and page.result.complete, 60.0)
    session = load_session(folder)
    keys = sorted((c.station, c.view) for c in session.captures)
    assert keys == sorted(small_plan().capture_keys())  # each view once, none lost
    assert page.progress.bar.value() == page.progress.bar.maximum() == 12
    assert page.controller.state is MissionState.FINISHED

    # the map follows the base's telemetry: it ends at the last station
    def at_last_station() -> bool:
        pose = page.map.base_pose
        return pose is not None and abs(pose[0] - 3.2) < 0.1 and abs(pose[1] - 0.0) < 0.1

    assert wait_until(at_last_station, 5.0), page.map.base_pose
    assert page.map.colours == {5: DONE, 6: DONE, 3: DONE}
    assert page.map.by_colour[DONE].data["data"].tolist() == [5, 6, 3]
    icons = [page.progress.grid.item(r, c) for r in range(3) for c in range(4)]
    assert all(item is not None and not item.icon().isNull() for item in icons[-4:])


def test_closing_during_a_mission_asks_then_stops_cleanly(
    make_window: Callable[..., MainWindow], wait_until: Wait, monkeypatch: pytest.MonkeyPatch
) -> None:
    window, page = connected_page(make_window, wait_until)
    page.start_button.click()
    assert wait_until(lambda: page.progress.captured >= 1)
    questions: list[str] = []
    monkeypatch.setattr("ui.mission.page.ask", lambda _p, _t, text: questions.append(text) or False)
    window.close()
    assert window.isVisible() and page.controller.busy  # the operator said no
    monkeypatch.setattr("ui.mission.page.ask", lambda _p, _t, text: questions.append(text) or True)
    window.close()
    assert len(questions) == 2 and "mission" in questions[0]
    assert not window.isVisible()
    assert page.controller.runner is not None
    result = page.controller.runner.result
    assert result is not None and result.outcome in (Outcome.STOPPED, Outcome.COMPLETE)
    assert window.context.hub.rig is None  # devices closed


def test_start_without_devices_is_refused_with_a_notice(
    make_window: Callable[..., MainWindow], wait_until: Wait
) -> None:
    window = make_window()
    page = window.pages["mission"]
    assert isinstance(page, MissionPage)
    page.start()
    assert wait_until(lambda: bool(window.notices.cards()), 5.0)
    assert "not connected" in window.notices.cards()[0].label.text()


def test_plan_editor_validates_saves_and_loads(
    make_window: Callable[..., MainWindow], tmp_path: Path
) -> None:
    page = make_window().pages["mission"]
    assert isinstance(page, MissionPage)
    editor = page.editor
    editor.set_plan(small_plan())
    editor.table.item(1, 1).setText("4.8")  # station 6 moves east
    assert editor.valid and editor.plan().station(6).x_m == pytest.approx(4.8)
    assert page.map.plan is not None and page.map.plan.station(6).x_m == pytest.approx(4.8)
    editor.table.item(0, 2).setText("north")
    assert not editor.valid and "stations.0.y_m" in editor.error.text()
    assert editor.plan().station(5).y_m == pytest.approx(1.6)  # the last valid plan is kept
    editor.table.item(0, 2).setText("1.6")
    editor.reference.setValue(9)
    assert "reference station 9" in editor.error.text()
    editor.reference.setValue(5)
    assert editor.valid
    path = tmp_path / "small.yaml"
    editor.save(path)
    assert load_plan(path) == editor.plan()
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nstations: [{number: 1, x_m: .nan, y_m: 0}]\n")
    editor.load(bad)
    assert "bad.yaml" in editor.error.text() and "x_m" in editor.error.text()
    editor.load(path)
    assert editor.valid and editor.plan().name == "small" and editor.path == path


def usable(page: MissionPage) -> bool:
    """The operator can act: Start, Resume and the plan editor are enabled."""
    return (
        page.start_button.isEnabled()
        and page.resume_button.isEnabled()
        and page.editor.isEnabled()
        and not page.controller.busy
    )


@pytest.mark.parametrize("kind", ["empty", "missing", "broken plan"])
def test_a_bad_resume_folder_leaves_the_page_usable_and_speaks_gui(
    make_window: Callable[..., MainWindow], wait_until: Wait, tmp_path: Path, kind: str
) -> None:
    window, page = connected_page(make_window, wait_until)
    folder = tmp_path / "chosen"
    if kind != "missing":
        folder.mkdir()
    if kind == "broken plan":
        (folder / "mission-plan.yaml").write_text("stations: [oops\n")
    page.resume(folder)
    assert wait_until(lambda: bool(window.notices.cards()) and usable(page), 20.0)
    notice = window.context.notifier.history[-1]
    assert notice.title == "Mission not started"
    text = f"{notice.message} {notice.advice}"
    assert "`fieldapp" not in text and "fieldapp mission" not in text, text
    if kind == "empty":
        assert "choose another folder" in text
    assert page.controller.state is MissionState.IDLE
    page.start_button.click()  # and the operator can carry on at once
    assert wait_until(lambda: page.result is not None or page.progress.captured >= 1, 30.0)
    window.emergency_stop()
    assert wait_until(lambda: page.result is not None, 20.0)
    assert usable(page)


def test_a_failed_connect_leaves_a_clear_way_on(
    make_window: Callable[..., MainWindow], wait_until: Wait
) -> None:
    from fieldapp.rig import RigError

    def refuse(_devices: object) -> object:
        raise RigError("table on /dev/ttyUSB0: no such port (try `fieldapp table --port "
                       "/dev/ttyUSB0 status`)")  # fmt: skip

    window = make_window(opener=refuse)
    page = window.pages["mission"]
    assert isinstance(page, MissionPage)
    window.toggle_connection()
    assert wait_until(lambda: bool(window.notices.cards()), 20.0)
    notice = window.context.notifier.history[-1]
    assert "`fieldapp" not in f"{notice.message} {notice.advice}"
    assert window.connect_button.isEnabled() and window.connect_button.text() == "Connect"
    assert not page.start_button.isEnabled() and "press Connect" in page.hint_label.text()
    assert page.editor.isEnabled()


def test_stop_while_the_mission_is_being_set_up_starts_nothing(
    make_window: Callable[..., MainWindow], wait_until: Wait
) -> None:
    window, page = connected_page(make_window, wait_until)
    page.start_button.click()
    assert page.controller.busy and page.controller.runner is None  # setting up on a worker
    window.emergency_stop()
    assert wait_until(lambda: usable(page), 20.0)
    assert page.controller.runner is None
    assert "STOP was pressed" in window.context.notifier.history[-1].message


def test_a_mission_thread_that_dies_is_shown_and_leaves_the_page_usable(
    make_window: Callable[..., MainWindow], wait_until: Wait, monkeypatch: pytest.MonkeyPatch
) -> None:
    window, page = connected_page(make_window, wait_until)

    def die(*_args: object, **_kwargs: object) -> None:
        raise MemoryError("injected: the mission's thread dies")

    monkeypatch.setattr("fieldapp.mission.execute.capture_one", die)
    page.start_button.click()
    assert wait_until(lambda: page.result is not None, 30.0)
    assert page.result is not None and page.result.outcome is Outcome.FAILED
    assert page.controller.state is MissionState.FAILED
    notice = window.context.notifier.history[-1]
    assert "injected" in notice.message or "injected" in notice.advice
    assert usable(page)
    window.toggle_connection()  # Disconnect is not refused
    assert wait_until(lambda: not window.context.hub.connected, 20.0)
