"""Correcting the plants by hand in the results panel: merge the plants selected in the table,
split one by clicking its stems in the 3D view or on the map (or typing them:
:mod:`ui.results.stem_picking`), delete a phantom, renumber a plant, undo (Ctrl+Z). The
corrections are applied, the plants measured again and the folder reread on a worker; the
table, 3D view and map then show the corrected plot with the plants the correction made
selected and highlighted. A new reconstruction gets the saved corrections again
(:mod:`fieldapp.results.corrected`)."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from PySide6 import QtCore, QtGui, QtWidgets

from fieldapp.errors import FieldappError
from fieldapp.recon.settings import ReconstructionSettings
from fieldapp.results.corrections import (
    Corrections,
    Delete,
    Merge,
    PlantRef,
    Relabel,
    Split,
    describe,
    read_corrections,
)
from ui.results.data import PlotResults, load_results_dir
from ui.results.scene import CloudScene, build_scene
from ui.results.stem_picking import StemPicker
from ui.workers import WorkerSet

if TYPE_CHECKING:
    from fieldapp.results.corrected import Result
    from ui.results.panel import ResultsPanel

log = logging.getLogger(__name__)

CORRECTED_BRUSH = QtGui.QBrush(QtGui.QColor(255, 236, 160))
AUTHOR_TIP = (
    "Your name, kept as the author of each correction you make: in corrections.json in the "
    "results folder and in the results database. It starts as the computer's login name; "
    "type yours."
)


@dataclass(frozen=True)
class Corrected:
    """What a worker hands back: the application's result and the folder reread."""

    result: Result
    plot: PlotResults
    scene: CloudScene
    db_problem: str = ""
    """Why the results database could not keep them (they are in the folder all the same)."""


def _job(
    folder: Path,
    change: Any,
    settings: ReconstructionSettings,
    db_path: Path | None,
    session_id: str,
) -> Corrected:
    """On the worker: apply (``change(folder, settings)``), keep in the database, reread."""
    result: Result = change(folder, settings)
    problem = ""
    if db_path is not None:
        from fieldapp.results.db import ResultsDB

        try:
            with ResultsDB.open(db_path) as db:
                db.save_corrections(session_id, folder)
        except FieldappError as error:
            problem = str(error)
    plot = load_results_dir(folder)
    return Corrected(result, plot, build_scene(plot), problem)


class CorrectionBar(QtWidgets.QWidget):
    """The correction actions of ``panel``; ``applied(Result)`` after each application."""

    applied = QtCore.Signal(object)

    def __init__(self, panel: ResultsPanel) -> None:
        super().__init__(panel)
        self.panel = panel
        self.corrections = Corrections()
        self.workers = WorkerSet()
        self._showing_own = False
        self.involved: list[int] = []
        """The plants the last correction applied made or gave back (selected after it)."""
        self._build()
        panel.results_shown.connect(self._shown)
        panel.runner.succeeded.connect(self._reconstructed)
        self._update()

    @property
    def split_plant(self) -> int | None:
        """The plant whose stems are being picked (None: no split being prepared)."""
        return self.picker.plant

    # --- the actions -------------------------------------------------------------------

    def merge(self) -> None:
        plants = self.selected_plants()
        if len(plants) < 2:
            raise FieldappError("merge: select two or more plants in the table")
        refs = [self._ref(p) for p in plants]
        self._change(add=Merge(plants=refs, into=min(plants), author=self._author()))

    def start_split(self) -> None:
        """Pick the stems of the selected plant in the 3D view or on the map (or type them),
        then split. The plant is the one selected now, whatever is clicked meanwhile."""
        plant = self._one("split")
        results = self.panel.results
        if results is None or plant not in results.plant_clouds:
            raise FieldappError(f"plant {plant} has no points in this results folder")
        self.picker.start(plant, results.plant_clouds[plant].points)
        self.status.setText(
            f"split plant {plant}: click each stem near its foot (3D view or map), then Apply split"
        )

    def split(self) -> None:
        plant = self.split_plant if self.split_plant is not None else self._one("split")
        stems = self.picker.stems_xy_m()
        if len(stems) < 2:
            raise FieldappError("split: pick two or more stems")
        numbers = self._free_numbers(len(stems) - 1)
        operation = Split(
            plant=self._ref(plant),
            stems_xy_m=stems,
            into=[plant, *numbers],
            author=self._author(),
        )
        self._end_split()
        self._change(add=operation)

    def delete(self) -> None:
        plant = self._one("delete")
        self._change(add=Delete(plant=self._ref(plant), author=self._author()))

    def renumber(self) -> None:
        plant = self._one("renumber")
        operation = Relabel(plant=self._ref(plant), into=self.number.value(), author=self._author())
        self._change(add=operation)

    def undo(self) -> None:
        if not self.corrections.operations:
            raise FieldappError("undo: no correction to undo")
        self._change(undo=True)

    # --- what the panel shows ----------------------------------------------------------

    def selected_plants(self) -> list[int]:
        """The plants of the rows selected in the table, in the table's order."""
        panel = self.panel
        rows = sorted(panel.table.selectionModel().selectedRows(), key=lambda i: i.row())
        model = panel.plant_model
        return [model.plants[panel.proxy.mapToSource(index).row()].plant for index in rows]

    def _one(self, action: str) -> int:
        plants = self.selected_plants()
        if len(plants) != 1:
            raise FieldappError(f"{action}: select one plant in the table")
        return plants[0]

    def _ref(self, plant: int) -> PlantRef:
        results = self.panel.results
        if results is None or plant not in results.plant_clouds:
            raise FieldappError(f"plant {plant} has no points in this results folder")
        from fieldapp.results.corrected import centroid_xy_m

        return PlantRef(plant=plant, xy_m=centroid_xy_m(results.plant_clouds[plant].points))

    def _free_numbers(self, count: int) -> list[int]:
        results = self.panel.results
        top = max((p.plant for p in results.plants), default=0) if results else 0
        return list(range(top + 1, top + 1 + count))

    def _author(self) -> str:
        return self.author.text().strip()

    # --- applying on a worker ----------------------------------------------------------

    def _change(self, add: Any = None, undo: bool = False, reapply: bool = False) -> None:
        results = self.panel.results
        if results is None:
            raise FieldappError("open results first")
        if self.workers.busy:
            raise FieldappError("a correction is being applied: wait for it")
        corrections = self.corrections.model_copy(update={"session": results.session_id})
        # the replay and the trait code (SciPy, Open3D): loaded at the first correction, not
        # with the window
        from fieldapp.results.corrected import add_correction, apply_corrections, undo_correction

        change: Any
        self.involved = []
        if add is not None:
            self.status.setText(f"{describe(add)}…")
            self.involved = made_by(add)

            def change(folder: Path, settings: ReconstructionSettings) -> Result:
                return add_correction(folder, corrections, add, settings)
        elif undo:
            self.status.setText(f"undo {describe(corrections.operations[-1])}…")
            self.involved = undone_by(corrections.operations[-1])

            def change(folder: Path, settings: ReconstructionSettings) -> Result:
                return undo_correction(folder, corrections, settings)
        else:
            self.status.setText("applying the saved corrections to the new reconstruction…")

            def change(folder: Path, settings: ReconstructionSettings) -> Result:
                return apply_corrections(folder, corrections, settings)

        db_path = self.panel.settings.paths.results_db
        arguments = (results.results_dir, change, self.panel.settings.reconstruction)
        self.workers.run(
            lambda: _job(*arguments, db_path, results.session_id), self._done, self._failed
        )
        self._update()

    def _done(self, corrected: Corrected) -> None:
        shown = self.panel.results
        if shown is None or shown.results_dir != corrected.plot.results_dir:
            self.status.setText(f"corrections applied to {corrected.plot.results_dir}")
            self._update()
            return  # another folder was opened meanwhile
        self.corrections = corrected.result.corrections
        self._showing_own = True
        try:
            self.panel.show_results(corrected.plot, corrected.scene)
        finally:
            self._showing_own = False
        present = {p.plant for p in corrected.plot.plants}
        self.select_plants([p for p in self.involved if p in present])
        self.panel.stage.setText(f"corrected: {len(present)} plants")  # not the run's count
        applied = self.corrections.applied
        unmatched = applied.unmatched if applied else []
        count = len(self.corrections.operations)
        self.status.setText(
            f"{count} correction{'s' if count != 1 else ''}"
            + (f"; {len(unmatched)} could not be applied" if unmatched else "")
        )
        if unmatched:
            self.panel.error.emit("corrections not applied:\n" + "\n".join(unmatched))
        if corrected.db_problem:
            self.panel.error.emit(
                f"corrections kept in the results folder, not in the results database: "
                f"{corrected.db_problem}"
            )
        self.applied.emit(corrected.result)
        self._update()

    def _failed(self, error: BaseException) -> None:
        self.status.setText(f"⚠ {str(error).splitlines()[0]}")
        self.panel.error.emit(f"correction: {error}")
        self._update()

    # --- slots -------------------------------------------------------------------------

    def _shown(self, results: PlotResults) -> None:
        """New results on screen: their corrections; applied again when a reconstruction has
        overwritten the folder since."""
        self._mark(results)
        if self._showing_own:
            return
        self._end_split()
        try:
            saved = read_corrections(results.results_dir)
        except FieldappError as error:
            self.corrections = Corrections()
            self.panel.error.emit(f"corrections: {error}")
            self._update()
            return
        self.corrections = saved or Corrections()
        self._update()
        from fieldapp.results.corrected import snapshot_is_current

        if saved is not None and not snapshot_is_current(results.results_dir, saved):
            self._report("apply corrections", lambda: self._change(reapply=True))

    def _reconstructed(self, _outcome: object) -> None:
        """A reconstruction into a folder without corrections: the session's corrections
        saved from another folder (results database) are applied to it."""
        self._report("apply corrections", self._carry_over)

    def _carry_over(self) -> None:
        results = self.panel.results
        db_path = self.panel.settings.paths.results_db
        if results is None or self.corrections.operations or self.workers.busy:
            return
        if not db_path.is_file():
            return
        from fieldapp.results.db import ResultsDB

        with ResultsDB.open(db_path, create=False) as db:
            saved = db.corrections(results.session_id)
        if saved is None or saved[0] == results.results_dir.resolve():
            return
        document = Corrections.model_validate(saved[1])
        self.corrections = document.model_copy(update={"applied": None})
        self._change(reapply=True)

    def _end_split(self) -> None:
        self.picker.end()
        self.status.setText("")

    def add_stem(self, x_m: float, y_m: float) -> None:
        """Add a stem point (map frame) to the split being prepared."""
        self.picker.add(x_m, y_m)

    def select_plants(self, plants: list[int]) -> None:
        """Select ``plants`` in the table (the first current) and highlight exactly their
        points in the 3D view and their circles on the map."""
        panel = self.panel
        panel.select_plant(plants[0] if plants else None)
        selection = panel.table.selectionModel()
        flags = QtCore.QItemSelectionModel.SelectionFlag
        for plant in plants[1:]:
            row = panel.plant_model.row_of(plant)
            if row is not None:
                index = panel.proxy.mapFromSource(panel.plant_model.index(row, 0))
                selection.select(index, flags.Select | flags.Rows)
        panel.view3d.highlight(plants)
        panel.map.highlight(plants)

    def _mark(self, results: PlotResults) -> None:
        """Colour the table rows of the plants corrected by hand."""
        saved = read_corrections_quietly(results.results_dir)
        applied = saved.applied if saved is not None else None
        corrected = set(applied.corrected) if applied is not None else set()
        model = self.panel.plant_model
        for row, record in enumerate(model.plants):
            if record.plant not in corrected:
                continue
            for column in range(model.columnCount()):
                item = model.item(row, column)
                item.setBackground(CORRECTED_BRUSH)
                item.setToolTip("corrected by hand: measured again from its points")

    def _update(self) -> None:
        busy = self.workers.busy
        shown = self.panel.results is not None
        for action in (self.merge_action, self.split_action, self.delete_action):
            action.setEnabled(shown and not busy)
        self.renumber_action.setEnabled(shown and not busy)
        self.undo_action.setEnabled(shown and not busy and bool(self.corrections.operations))
        last = self.corrections.operations[-1] if self.corrections.operations else None
        self.undo_action.setToolTip(f"Undo: {describe(last)}" if last else "Nothing to undo")

    # --- building ----------------------------------------------------------------------

    def _build(self) -> None:
        self.toolbar = QtWidgets.QToolBar("Corrections")
        self.merge_action = self._action(
            "Merge", self.merge, "Merge the plants selected in the table (Ctrl-click 2 or more)"
        )
        self.split_action = self._action(
            "Split…",
            self.start_split,
            "Split the plant selected in the table: then click each of its stems in the 3D "
            "view or on the map",
        )
        self.delete_action = self._action(
            "Delete", self.delete, "The plant selected in the table is no plant: delete it"
        )
        self.renumber_action = self._action(
            "Renumber as", self.renumber, "Give the plant selected in the table this number"
        )
        self.number = QtWidgets.QSpinBox()
        self.number.setRange(1, 99_999)
        self.toolbar.addWidget(self.number)
        self.undo_action = self._action("Undo", self.undo, "Undo the last correction")
        self.undo_action.setShortcut(QtGui.QKeySequence.StandardKey.Undo)
        self.undo_action.setShortcutContext(QtCore.Qt.ShortcutContext.WidgetWithChildrenShortcut)
        self.panel.addAction(self.undo_action)  # Ctrl+Z anywhere in the results panel
        self.toolbar.addSeparator()
        self.author = QtWidgets.QLineEdit(_login())
        self.author.setPlaceholderText("your name")
        self.author.setToolTip(AUTHOR_TIP)
        self.author.setMaximumWidth(160)
        self.author_label = QtWidgets.QLabel(" Corrected by: ")
        self.author_label.setToolTip(AUTHOR_TIP)
        self.author_label.setBuddy(self.author)
        self.toolbar.addWidget(self.author_label)
        self.toolbar.addWidget(self.author)
        self.status = QtWidgets.QLabel("")
        self.picker = StemPicker(self.panel)
        self.picker.apply_requested.connect(lambda: self._report("split", self.split))
        self.picker.cancel.clicked.connect(self._end_split)
        self.split_row = self.picker
        self.stems = self.picker.stems
        top = QtWidgets.QHBoxLayout()
        top.setContentsMargins(0, 0, 0, 0)
        top.addWidget(self.toolbar)
        top.addWidget(self.status, 1)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(top)
        layout.addWidget(self.split_row)

    def _action(self, text: str, slot: Any, tip: str) -> QtGui.QAction:
        action = self.toolbar.addAction(text)
        action.setToolTip(tip)
        action.triggered.connect(lambda: self._report(text.rstrip("…").lower(), slot))
        return action

    def _report(self, action: str, call: Any) -> None:
        try:
            call()
        except FieldappError as error:
            self.status.setText(f"⚠ {str(error).splitlines()[0]}")
            self.panel.error.emit(f"{action}: {error}")

    def shutdown(self) -> None:
        self.workers.wait()


def read_corrections_quietly(folder: Path) -> Corrections | None:
    """The folder's corrections, ``None`` when it has none or they cannot be read."""
    try:
        return read_corrections(folder)
    except FieldappError:
        return None


def _login() -> str:
    """The login name, the author of corrections until the operator types theirs."""
    import getpass

    try:
        return getpass.getuser()
    except (OSError, KeyError):
        return ""


def made_by(operation: Merge | Split | Delete | Relabel) -> list[int]:
    """The plants ``operation`` leaves in the plot (what to select after it)."""
    if isinstance(operation, Merge | Relabel):
        return [operation.into]
    if isinstance(operation, Split):
        return list(operation.into)
    return []


def undone_by(operation: Merge | Split | Delete | Relabel) -> list[int]:
    """The plants undoing ``operation`` gives back."""
    if isinstance(operation, Merge):
        return [p.plant for p in operation.plants]
    return [operation.plant.plant]
