"""A calibration wizard as a full page of the Calibrate area, the way the ROS and MATLAB
calibrators show one workspace: a bar with the way back to the calibration overview and the
wizard's name, the list of its steps (the current one marked, the solve said to be running),
and the wizard itself, embedded (no window of its own) with its pictures and verdict.

Leaving for the overview (or another page of the window) keeps the wizard as it is, a solve
under way included; Alt+Left is the wizard's Back, and the overview from its first step."""

from __future__ import annotations

from typing import TYPE_CHECKING

from PySide6 import QtCore, QtGui, QtWidgets

if TYPE_CHECKING:  # the wizards' module imports the solvers: not at start-up
    from ui.calibration.pages import CalibrationWizard

BAR_STYLE = "#calibrationBar { background:#eceff1; border-bottom:1px solid #b0bec5; }"


class Workspace(QtWidgets.QWidget):
    """``wizard`` shown as a page; ``overview_requested`` when the operator goes back."""

    overview_requested = QtCore.Signal()

    def __init__(
        self, title: str, wizard: CalibrationWizard, parent: QtWidgets.QWidget | None = None
    ) -> None:
        super().__init__(parent)
        self.title, self.wizard = title, wizard
        wizard.setWindowFlags(QtCore.Qt.WindowType.Widget)  # a page, not a dialog
        self.back_button = QtWidgets.QPushButton("< Calibration overview")
        self.back_button.setToolTip(
            "Back to the list of calibrations; this one stays as it is (a solve keeps running)"
        )
        self.back_button.clicked.connect(self.overview_requested)
        self.heading = QtWidgets.QLabel(f"<b style='font-size:15px'>{title}</b>")
        self.step = QtWidgets.QLabel("")
        self.steps = QtWidgets.QListWidget()
        self.steps.setObjectName("calibrationSteps")
        self.steps.setFocusPolicy(QtCore.Qt.FocusPolicy.NoFocus)
        self.steps.setSelectionMode(QtWidgets.QAbstractItemView.SelectionMode.NoSelection)
        self.steps.setFixedWidth(240)
        self.steps.setWordWrap(True)
        self.steps.setTextElideMode(QtCore.Qt.TextElideMode.ElideNone)
        self.steps.setHorizontalScrollBarPolicy(QtCore.Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.steps.setStyleSheet("#calibrationSteps::item { padding:8px 4px; }")
        for number, page_id in enumerate(wizard.pageIds(), start=1):
            self.steps.addItem(f"{number}. {wizard.page(page_id).title()}")
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self._bar())
        row = QtWidgets.QHBoxLayout()
        row.addWidget(self.steps)
        row.addWidget(wizard, 1)
        layout.addLayout(row, 1)
        back = QtGui.QShortcut(QtGui.QKeySequence("Alt+Left"), self)  # not Backspace
        back.setContext(QtCore.Qt.ShortcutContext.WindowShortcut)  # only the page shown
        back.activated.connect(self.go_back)
        wizard.currentIdChanged.connect(lambda _: self.update_steps())
        wizard.solve.completeChanged.connect(self.update_steps)
        self.update_steps()

    def _bar(self) -> QtWidgets.QWidget:
        bar = QtWidgets.QWidget()
        bar.setObjectName("calibrationBar")
        bar.setAttribute(QtCore.Qt.WidgetAttribute.WA_StyledBackground, True)
        bar.setStyleSheet(BAR_STYLE)
        row = QtWidgets.QHBoxLayout(bar)
        row.setContentsMargins(6, 4, 6, 4)
        row.addWidget(self.back_button)
        row.addSpacing(12)
        row.addWidget(self.heading)
        row.addStretch(1)
        row.addWidget(self.step)
        return bar

    def step_index(self) -> int:
        """0-based index of the wizard's current step (-1 before it starts)."""
        ids = self.wizard.pageIds()
        current = self.wizard.currentId()
        return ids.index(current) if current in ids else -1

    def state_text(self) -> str:
        """Where the wizard stands, in words: for the overview's button and this bar."""
        index = self.step_index()
        if index < 0:
            return "not started"
        words = f"step {index + 1} of {self.steps.count()}: {self.wizard.currentPage().title()}"
        return words + (" (solving...)" if self.wizard.solving else "")

    @QtCore.Slot()
    def update_steps(self) -> None:
        index = self.step_index()
        for row in range(self.steps.count()):
            item = self.steps.item(row)
            text = item.text().removesuffix(" (solving...)")
            if row == index and self.wizard.solving:
                text += " (solving...)"
            item.setText(text)
            font = item.font()
            font.setBold(row == index)
            item.setFont(font)
            item.setForeground(QtGui.QColor("#1565c0" if row == index else "#37474f"))
            item.setBackground(QtGui.QColor("#e3f2fd" if row == index else "transparent"))
        self.steps.doItemsLayout()  # a bold step may wrap onto two lines
        self.step.setText(self.state_text())

    @QtCore.Slot()
    def go_back(self) -> None:
        """The wizard's Back when it has one enabled; from its first step, the overview."""
        back = self.wizard.button(QtWidgets.QWizard.WizardButton.BackButton)
        if self.step_index() <= 0:
            self.overview_requested.emit()
        elif back.isVisible() and back.isEnabled():
            self.wizard.back()
