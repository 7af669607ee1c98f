"""The Mission page: the plan (edit, load, save) and manual set-up moves on the left, the map
with the base's live pose and the progress grid in the middle, the controls on top.

Start captures the plan into a new session folder under the sessions folder; Pause holds at
the next step boundary; Abort ends there; STOP (Esc, in the window's header) holds the table
and stops the base at once. A mission that did not finish can be resumed: it captures only
what its session still misses.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from PySide6 import QtCore, QtWidgets

from fieldapp.mission.events import MissionResult, MissionState, Outcome, ViewCaptured
from ui.mission.controller import MissionController
from ui.mission.plan_editor import PlanEditor
from ui.mission.plan_map import ACTIVE, DONE, LOW, PlanMap
from ui.mission.progress import ProgressPanel
from ui.mission.setup_panel import SetupPanel
from ui.notifications import Level, Notice, notice_from_error
from ui.wording import gui_text

if TYPE_CHECKING:
    from devices.base.protocol import Pose
    from fieldapp.mission.plan import MissionPlan
    from ui.context import AppContext

log = logging.getLogger(__name__)

STATE_COLOURS = {
    MissionState.IDLE: "#607d8b",
    MissionState.RUNNING: "#2e7d32",
    MissionState.PAUSED: "#ef6c00",
    MissionState.STOPPING: "#c62828",
    MissionState.FINISHED: "#1565c0",
    MissionState.FAILED: "#c62828",
}
BIG = "QPushButton { font-size:15px; font-weight:bold; padding:6px 16px; }"
BUTTON_TIPS = {
    True: "Capture the plan into a new session folder",
    False: "Capture what an interrupted session still misses",
}
START_ADVICE = "Check the plan and the folder, then press Start or Resume session... again."


def ask(parent: QtWidgets.QWidget, title: str, text: str) -> bool:
    """Yes/No question to the operator (tests replace it)."""
    answer = QtWidgets.QMessageBox.question(parent, title, text)
    return answer == QtWidgets.QMessageBox.StandardButton.Yes


class MissionPage(QtWidgets.QWidget):
    """Emits :attr:`session_finished` with the session folder when a mission ends."""

    session_finished = QtCore.Signal(object)

    def __init__(self, context: AppContext, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.context = context
        self.controller = MissionController(context.hub, self)
        self.controller.battery = context.settings.battery
        self.result: MissionResult | None = None
        self.station_views: dict[int, set[int]] = {}
        self._build()
        self._wire()
        self._plan_changed(self.editor.plan())
        self._update_buttons()

    def _build(self) -> None:
        self.editor = PlanEditor(self.context.ui_state)
        self.setup = SetupPanel(self.context)
        tabs = QtWidgets.QTabWidget()
        tabs.addTab(self.editor, "Plan")
        tabs.addTab(self.setup, "Set-up")
        tabs.setMinimumWidth(360)
        self.map = PlanMap()
        self.progress = ProgressPanel()
        middle = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)
        middle.addWidget(self.map)
        middle.addWidget(self.progress)
        middle.setSizes([380, 420])
        split = QtWidgets.QSplitter()
        split.addWidget(tabs)
        split.addWidget(middle)
        split.setSizes([380, 900])
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(self._controls())
        layout.addWidget(split, 1)

    def _controls(self) -> QtWidgets.QHBoxLayout:
        self.start_button = QtWidgets.QPushButton("▶ Start")
        self.pause_button = QtWidgets.QPushButton("❚❚ Pause")
        self.abort_button = QtWidgets.QPushButton("Abort")
        self.resume_button = QtWidgets.QPushButton("Resume session...")
        for button in (self.start_button, self.pause_button, self.abort_button, self.resume_button):
            button.setStyleSheet(BIG)
        self.start_button.setToolTip(BUTTON_TIPS[True])
        self.abort_button.setToolTip("End the mission after the current step")
        self.resume_button.setToolTip(BUTTON_TIPS[False])
        self.state_label = QtWidgets.QLabel()
        self.hint_label = QtWidgets.QLabel()
        self.hint_label.setStyleSheet("color:#ef6c00")
        self.folder_label = QtWidgets.QLabel()
        self.folder_label.setTextInteractionFlags(
            QtCore.Qt.TextInteractionFlag.TextSelectableByMouse
        )
        row = QtWidgets.QHBoxLayout()
        for button in (self.start_button, self.pause_button, self.abort_button, self.resume_button):
            row.addWidget(button)
        row.addSpacing(12)
        row.addWidget(self.state_label)
        row.addWidget(self.hint_label)
        row.addWidget(self.folder_label, 1)
        self._show_state(MissionState.IDLE)
        return row

    def _wire(self) -> None:
        c = self.controller
        self.start_button.clicked.connect(self.start)
        self.pause_button.clicked.connect(self.toggle_pause)
        self.abort_button.clicked.connect(c.abort)
        self.resume_button.clicked.connect(self.choose_and_resume)
        self.editor.plan_changed.connect(self._plan_changed)
        c.started.connect(self._started)
        c.failed_to_start.connect(self._failed_to_start)
        c.state_changed.connect(self._show_state)
        c.station_reached.connect(self.progress.add_station)
        c.station_reached.connect(lambda e: self.map.set_station_state(e.station, ACTIVE))
        c.view_captured.connect(self._view_captured)
        c.warning.connect(self.progress.add_warning)
        c.progress.connect(self.progress.set_progress)
        self.progress.view_opened.connect(self.open_view)
        c.finished.connect(self._finished)
        hub = self.context.hub
        hub.pose_received.connect(self._show_pose)
        hub.state_changed.connect(lambda _s: self._update_buttons())

    # --- controls ---------------------------------------------------------------------------

    @property
    def busy(self) -> bool:
        return self.controller.busy or self.setup.busy

    def new_folder(self, plan: MissionPlan) -> Path:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        return self.context.settings.paths.sessions_dir / f"{plan.name}-{stamp}"

    def start(self, folder: Path | None = None) -> None:
        if not self.editor.valid:
            self.context.notifier.warn(
                "Mission", self.editor.error.text(), "Fix the plan first.", topic="mission"
            )
            return
        settings = self.context.settings
        plan = self.editor.plan().model_copy(
            update={"devices": settings.devices, "incidents": settings.incidents}
        )
        folder = folder if isinstance(folder, Path) else self.new_folder(plan)
        self.folder_label.setText(f"starting {folder}...")
        self.controller.start(plan, folder)
        self._update_buttons()

    def choose_and_resume(self) -> None:
        start = self.controller.folder or self.context.ui_state.last_folder(
            "sessions", self.context.settings.paths.sessions_dir
        )
        name = QtWidgets.QFileDialog.getExistingDirectory(self, "Resume which session?", str(start))
        if name:
            self.context.ui_state.set_last_folder("sessions", Path(name))
            self.resume(Path(name))

    def resume(self, folder: Path) -> None:
        self.folder_label.setText(f"resuming {folder}...")
        self.controller.resume_session(folder)
        self._update_buttons()

    def toggle_pause(self) -> None:
        if self.controller.state is MissionState.PAUSED:
            self.controller.carry_on()
        else:
            self.controller.pause()

    def emergency_stop(self) -> None:
        """Called by the window's STOP (Esc): the mission ends now."""
        self.controller.stop()

    # --- mission events (GUI thread) --------------------------------------------------------

    def _plan_changed(self, plan: MissionPlan) -> None:
        if not self.controller.busy:
            self.map.show_plan(plan)
            self.setup.show_plan(plan)

    def _started(self, plan: MissionPlan, folder: Path) -> None:
        runner = self.controller.runner
        missing = set(runner.missing()) if runner is not None else set()
        done = [key for key in plan.capture_keys() if key not in missing]
        self.result = None
        self.station_views = {s: set() for s in plan.station_numbers()}
        for station, view in done:
            self.station_views[station].add(view)
        self.map.show_plan(plan)
        self.setup.show_plan(plan)
        for station, views in self.station_views.items():
            if len(views) == plan.views.count:
                self.map.set_station_state(station, DONE)
        self.progress.show_plan(plan, done)
        self.folder_label.setText(str(folder))
        self.progress.add_line(f"mission started in {folder} ({len(missing)} captures to take)")
        self._update_buttons()

    def _failed_to_start(self, error: BaseException) -> None:
        """Nothing started: say why and what to do; Start, Resume and the plan are usable."""
        self.folder_label.setText("")
        notice = notice_from_error("Mission not started", error, topic="mission")
        if not notice.advice:
            notice = replace(notice, advice=START_ADVICE)
        self.context.notifier.post(notice)
        self.progress.add_line(f"not started: {gui_text(notice.message)}")
        self._update_buttons()

    def _view_captured(self, event: ViewCaptured) -> None:
        self.progress.add_view(event)
        views = self.station_views.setdefault(event.station, set())
        views.add(event.view)
        plan = self.controller.runner.plan if self.controller.runner else None
        if plan is not None and len(views) == plan.views.count:
            self.map.set_station_state(event.station, DONE if event.quality_ok else LOW)

    def _finished(self, result: MissionResult) -> None:
        self.result = result
        for line in result.lines():
            self.progress.add_line(gui_text(line))
        level = Level.INFO if result.outcome is Outcome.COMPLETE else Level.WARNING
        if result.outcome is Outcome.FAILED:
            level = Level.ERROR
        advice = "" if result.complete else "Press Resume session... to capture what is missing."
        if result.fault is not None:
            advice = result.fault.advice
        self._show_outcome(result)
        self.progress.finish(
            f"{result.outcome.value}: {result.captured} captured, {len(result.missing)} missing"
        )
        summary = result.lines()[:2]
        if result.fault is not None:  # the reason, whatever it is: a fault, a dead thread
            summary = [summary[0], f"{result.fault.device}: {result.fault.what}"]
        title = f"Mission {result.outcome.value}"  # the notifier drops its repeat in summary
        message = "; ".join(summary)
        # topic: this outcome replaces an open "Mission not started" or earlier outcome
        self.context.notifier.post(Notice(level, title, message, advice, topic="mission"))
        if self.controller.folder is not None:
            self.context.ui_state.set_last_folder("sessions", self.controller.folder)
            if result.captured:  # a session with nothing in it has nothing to show
                self.session_finished.emit(self.controller.folder)
        self._update_buttons()

    def open_view(self, station: int, view: int) -> QtWidgets.QWidget | None:
        """Show the capture's depth and colour large (double-click on a thumbnail); ``None``
        when it cannot be read (a notice says why)."""
        from fieldapp.errors import FieldappError
        from fieldapp.io.images import ImageError
        from ui.mission.depth_view import DepthViewer, read_view

        folder = self.controller.folder
        if folder is None:
            return None
        try:
            depth_m, color = read_view(folder, station, view)
        except (FieldappError, ImageError) as error:
            self.context.notifier.error(f"Station {station} view {view}", error)
            return None
        title = f"station {station}, view {view}: depth and colour"
        viewer = DepthViewer(title, depth_m, self, color=color)
        viewer.show()
        return viewer

    def _show_pose(self, pose: Pose) -> None:
        self.map.show_base(pose.x_m, pose.y_m, pose.yaw_deg)

    def _show_state(self, state: MissionState) -> None:
        if state in (MissionState.FINISHED, MissionState.FAILED) and self.result is not None:
            self._update_buttons()
            return
        colour = STATE_COLOURS[state]
        self.state_label.setText(
            f"<span style='font-size:15px; font-weight:bold; color:{colour}'>"
            f"{state.value.upper()}</span>"
        )
        self.pause_button.setText("▶ Continue" if state is MissionState.PAUSED else "❚❚ Pause")
        self.progress.set_paused(state is MissionState.PAUSED)
        self._update_buttons()

    def _show_outcome(self, result: MissionResult) -> None:
        colour = {Outcome.COMPLETE: "#2e7d32", Outcome.FAILED: "#c62828"}.get(
            result.outcome, "#ef6c00"
        )
        total = result.captured + len(result.missing)
        self.state_label.setText(
            f"<span style='font-size:15px; font-weight:bold; color:{colour}'>"
            f"{result.outcome.value.upper()}</span> {result.captured} of {total} captures"
        )

    def _update_buttons(self) -> None:
        connected = self.context.hub.connected
        state = self.controller.state
        active = state in (MissionState.RUNNING, MissionState.PAUSED)
        busy = self.controller.busy
        self.start_button.setEnabled(connected and not busy)
        self.resume_button.setEnabled(connected and not busy)
        hint = "" if connected or busy else "Devices not connected: press Connect (top right)."
        for button in (self.start_button, self.resume_button):
            button.setToolTip(hint or BUTTON_TIPS[button is self.start_button])
        self.hint_label.setText(hint)
        self.pause_button.setEnabled(active)
        self.abort_button.setEnabled(active)
        self.editor.setEnabled(not busy)
        self.setup.setEnabled(connected and not busy)

    # --- closing ----------------------------------------------------------------------------

    def confirm_close(self, parent: QtWidgets.QWidget) -> bool:
        if not self.busy:
            return True
        return ask(
            parent,
            "Mission running",
            "A mission or a manual move is running. Stop the devices and close?",
        )

    def shutdown(self) -> None:
        if self.setup.busy:
            self.context.hub.emergency_stop()
        self.controller.shutdown()
        self.setup.shutdown()
