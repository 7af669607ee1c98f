"""The Results page: open a session (or the one just captured) or a results folder,
reconstruct in a worker with stage-by-stage progress and cancel, then inspect the plot."""

from __future__ import annotations

import logging
from collections.abc import Callable
from functools import partial
from pathlib import Path

from PySide6 import QtCore, QtWidgets

from fieldapp.errors import FieldappError
from fieldapp.io.session import Session, load_session
from fieldapp.recon.progress import Progress
from fieldapp.settings import Settings
from ui.results.correction import CorrectionBar
from ui.results.data import PlotResults, load_results_dir
from ui.results.history import HistoryPanel
from ui.results.manual import ManualPanel
from ui.results.provenance import show_provenance
from ui.results.runner import (
    Outcome,
    ReconstructionRunner,
    choose_results_dir,
    default_results_dir,
)
from ui.results.scene import CloudScene, build_scene
from ui.results.tables import PlantTableModel, leaf_model, station_model
from ui.results.topmap import TopMap
from ui.results.view3d import CloudView
from ui.workers import WorkerSet

log = logging.getLogger(__name__)


class ResultsPanel(QtWidgets.QWidget):
    """``results_shown(PlotResults)`` once a plot is on screen; ``error(str)`` for the sink."""

    results_shown = QtCore.Signal(object)
    error = QtCore.Signal(str)

    def __init__(self, settings: Settings | None = None, parent: QtWidgets.QWidget | None = None):
        super().__init__(parent)
        self.settings = settings or Settings()
        self.session: Session | None = None
        self.results: PlotResults | None = None
        self.selected: int | None = None
        self._syncing_table = False  # select_plant is moving the table's selection itself
        self.runner = ReconstructionRunner(self)
        self.runner.progressed.connect(self._progressed)
        self.runner.succeeded.connect(self._succeeded)
        self.runner.failed.connect(self._failed)
        self.runner.cancelled.connect(self._cancelled)
        self._export_jobs = WorkerSet()
        layout = self._build()
        self.correction = CorrectionBar(self)  # merge, split, delete, renumber, undo
        layout.insertWidget(3, self.correction)
        self._set_running(False)

    # --- public API --------------------------------------------------------------------

    def open_session(self, folder: Path) -> None:
        """Load ``folder`` as the session to reconstruct; a bad folder raises FieldappError."""
        self.session = load_session(folder)
        self.results_dir.setText(str(default_results_dir(folder)))
        missing = len(self.session.missing())
        self.session_label.setText(
            f"session {self.session.id}: {len(self.session.captures)} captures, "
            f"stations {', '.join(map(str, self.session.stations()))}"
            + (f" ({missing} captures missing)" if missing else "")
        )
        self._set_running(False)

    def open_results(self, folder: Path) -> None:
        """Show a results folder written earlier (no reconstruction)."""
        results = load_results_dir(folder)
        self.show_results(results)
        if self.session is None:  # not "No session open." above the results shown
            self.session_label.setText(
                f"results of session {results.session_id} (its session is not open: open it "
                "to reconstruct again)"
            )

    def reconstruct(self) -> None:
        """Start reconstructing the open session in a worker."""
        if self.session is None:
            raise FieldappError("open a session first")
        folder = Path(self.results_dir.text().strip() or default_results_dir(self.session.folder))
        chosen = choose_results_dir(self, folder)
        if chosen is None:
            self.stage.setText(f"not reconstructed: the results in {folder} are kept")
            return
        self.results_dir.setText(str(chosen))
        self.runner.start(self.session, self.settings.reconstruction, chosen)
        self.stage.setText("starting…")
        self.progress.setValue(0)
        self._set_running(True)

    def cancel(self) -> None:
        self.runner.cancel()
        self.stage.setText("cancelling at the next step…")

    def show_results(self, results: PlotResults, scene: CloudScene | None = None) -> None:
        """Show ``results`` (``scene``: its drawing, when already built off the GUI thread)."""
        self.results, self.selected = results, None
        self.leaves.setModel(leaf_model([]))
        scene = scene or build_scene(results)
        self.view3d.show_scene(scene)
        self.map.show_scene(scene)
        self.plant_model.set_plants(results.plants, results.report)
        self._fit_table()
        reference = results.report.get("reference_station")
        self.stations.setModel(station_model(results.report, reference))
        self.warnings.clear()
        self.warnings.addItems(results.warnings or ["no warnings"])
        self.tabs.setTabText(
            self.tabs.indexOf(self.warnings), f"Warnings ({len(results.warnings)})"
        )
        self.manual.set_plants(results.plants)
        self.summary.setText(
            f"{results.session_id}: {len(results.plants)} plants, {len(results.cloud)} points "
            f"→ {results.results_dir}"
        )
        show_provenance(self.provenance, results.report.get("provenance"))
        self.export_button.setEnabled(True)
        self.history.record_button.setEnabled(True)
        self.results_shown.emit(results)

    def _fit_table(self) -> None:
        """The plant table's pane as wide as its columns (up to half the panel), so that the
        "found" column, last, shows each plant's flag without scrolling."""
        header = self.table.horizontalHeader()
        self.table.resizeColumnsToContents()
        wanted = header.length() + self.table.verticalScrollBar().sizeHint().width()
        wanted += 2 * self.table.frameWidth()
        total = sum(self.splitter.sizes())
        if total > 0 and wanted > self.splitter.sizes()[0]:
            width = min(wanted, total // 2)
            self.splitter.setSizes([width, total - width])

    def select_plant(self, plant: int | None) -> None:
        """Select ``plant`` everywhere: table row, 3D view and map."""
        if self.results is None or plant == self.selected:
            return
        self.selected = plant
        self.view3d.select(plant)
        self.map.select(plant)
        self.inspector.show_plant(plant)
        self.leaves.setModel(
            leaf_model([] if plant is None else self.results.leaves.get(plant, []))
        )
        row = None if plant is None else self.plant_model.row_of(plant)
        selection = self.table.selectionModel()
        self._syncing_table = True
        try:
            if row is None:
                self.table.clearSelection()
            else:
                index = self.proxy.mapFromSource(self.plant_model.index(row, 0))
                if not selection.isSelected(index):  # a plant of a multiple selection keeps it
                    flags = QtCore.QItemSelectionModel.SelectionFlag
                    selection.select(index, flags.ClearAndSelect | flags.Rows)
                selection.setCurrentIndex(index, QtCore.QItemSelectionModel.SelectionFlag.NoUpdate)
                self.table.scrollTo(index)
        finally:
            self._syncing_table = False

    def export_to(self, folder: Path) -> list[Path]:
        """Export the plot shown into ``folder`` (blocking; the button runs it in a worker)."""
        return self.export_job(folder)()

    def export_job(self, folder: Path) -> Callable[[], list[Path]]:
        """The export of what is shown, as plain data gathered here on the GUI thread, to run
        anywhere; raises :class:`FieldappError` when there is nothing to export."""
        if self.results is None:
            raise FieldappError("nothing to export: reconstruct or open results first")
        growth = {t: self._growth(t) for t in ("height", "width")}
        calibration = self.session.calibration.to_document() if self.session else None
        from ui.results.export import export_results  # matplotlib: only when exporting

        return partial(
            export_results,
            self.results,
            folder,
            self.manual.evaluation,
            growth,
            calibration,
            organ_evaluation=self.organ_accuracy.evaluation,
        )

    def shutdown(self) -> None:
        """Stop a running reconstruction (the main window calls this as it closes)."""
        self.runner.cancel()
        self.runner.wait()
        self._export_jobs.wait()
        self.correction.shutdown()

    # --- building ----------------------------------------------------------------------

    def _build(self) -> QtWidgets.QVBoxLayout:
        """The page's widgets; returns its layout (the correction bar goes in it later)."""
        open_session = QtWidgets.QPushButton("Open session…")
        open_session.clicked.connect(self._ask_session)
        open_results = QtWidgets.QPushButton("Open results…")
        open_results.clicked.connect(self._ask_results)
        self.session_label = QtWidgets.QLabel("No session open.")
        self.results_dir = QtWidgets.QLineEdit()
        self.results_dir.setPlaceholderText("results folder (default: <session>-results)")
        self.run_button = QtWidgets.QPushButton("Reconstruct")
        self.run_button.clicked.connect(self._run_clicked)
        self.cancel_button = QtWidgets.QPushButton("Cancel")
        self.cancel_button.clicked.connect(self.cancel)
        self.export_button = QtWidgets.QPushButton("Export…")
        self.export_button.clicked.connect(self._ask_export)
        self.progress = QtWidgets.QProgressBar()
        self.progress.setRange(0, 1000)
        self.stage = QtWidgets.QLabel("")
        self.summary = QtWidgets.QLabel("")
        self.provenance = QtWidgets.QLabel("")  # where the results came from; details as tooltip
        row1 = QtWidgets.QHBoxLayout()
        for widget in (open_session, open_results, self.session_label):
            row1.addWidget(widget)
        row1.addStretch(1)
        row2 = QtWidgets.QHBoxLayout()
        for control in (
            self.results_dir,
            self.run_button,
            self.cancel_button,
            self.progress,
            self.stage,
            self.export_button,
        ):
            row2.addWidget(control)
        self.plant_model = PlantTableModel(self)
        self.proxy = QtCore.QSortFilterProxyModel(self)
        self.proxy.setSourceModel(self.plant_model)
        self.proxy.setSortRole(QtCore.Qt.ItemDataRole.UserRole)
        self.table = QtWidgets.QTableView()
        self.table.setModel(self.proxy)
        self.table.setSortingEnabled(True)
        self.table.sortByColumn(0, QtCore.Qt.SortOrder.AscendingOrder)
        self.table.setSelectionBehavior(QtWidgets.QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setSelectionMode(QtWidgets.QAbstractItemView.SelectionMode.ExtendedSelection)
        self.table.verticalHeader().hide()
        self.table.horizontalHeader().setSectionResizeMode(
            QtWidgets.QHeaderView.ResizeMode.ResizeToContents
        )
        self.table.selectionModel().selectionChanged.connect(self._table_selected)
        self.view3d = CloudView()
        self.view3d.plant_clicked.connect(self.select_plant)
        self.map = TopMap()
        self.map.plant_clicked.connect(self.select_plant)
        self.stations = QtWidgets.QTableView()
        self.warnings = QtWidgets.QListWidget()
        self.leaves = QtWidgets.QTableView()
        self.leaves.setModel(leaf_model([]))
        self.leaves.verticalHeader().hide()
        self.manual = ManualPanel()
        self.history = HistoryPanel(self.settings.paths.results_db)
        self.history.record_button.clicked.connect(self._record_clicked)
        self.tabs = QtWidgets.QTabWidget()
        pages = (
            (self.view3d, "3D"),
            (self.map, "Map"),
            (self.leaves, "Leaves"),
            (self.stations, "Registration"),
            (self.warnings, "Warnings"),
            (self.manual, "Manual measurements"),
            (self.history, "History"),
        )
        for page, name in pages:
            self.tabs.setTabToolTip(self.tabs.addTab(page, name), name)  # whole where elided
        # every tab in sight, their names elided where the window is narrow: behind a scroll
        # arrow, History went unseen at 1500 pixels wide
        self.tabs.setUsesScrollButtons(False)
        self.tabs.setElideMode(QtCore.Qt.TextElideMode.ElideRight)
        splitter = self.splitter = QtWidgets.QSplitter()
        splitter.addWidget(self.table)
        splitter.addWidget(self.tabs)
        splitter.setStretchFactor(1, 3)
        splitter.setSizes([460, 1000])
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(row1)
        layout.addLayout(row2)
        layout.addWidget(self.summary)
        layout.addWidget(self.provenance)
        layout.addWidget(splitter, 1)
        self.export_button.setEnabled(False)
        self.history.record_button.setEnabled(False)
        self._build_organ_views()
        return layout

    def _build_organ_views(self) -> None:
        """The per-plant inspector (linked both ways with the plant table, the 3D view and
        the map through :meth:`select_plant`) and the organ accuracy: one block, its imports
        with it."""
        from ui.results.inspector import PlantInspector
        from ui.results.organ_accuracy import OrganAccuracyPanel

        self.inspector = PlantInspector(self.settings.reconstruction.plants)
        self.inspector.plant_selected.connect(self.select_plant)
        self.tabs.insertTab(1, self.inspector, "Plant")
        self.organ_accuracy = OrganAccuracyPanel()
        accuracy = self.tabs.insertTab(
            self.tabs.indexOf(self.manual) + 1, self.organ_accuracy, "Organ accuracy"
        )
        self.tabs.setTabToolTip(accuracy, "Organ accuracy")
        self.results_shown.connect(self.inspector.set_results)
        self.results_shown.connect(self.organ_accuracy.set_results)

    # --- slots -------------------------------------------------------------------------

    def _set_running(self, running: bool) -> None:
        self.run_button.setEnabled(not running and self.session is not None)
        self.cancel_button.setEnabled(running)

    def _progressed(self, event: Progress) -> None:
        self.progress.setValue(round(1000 * event.fraction))
        self.stage.setText(f"{event.stage}: {event.message}")

    def _succeeded(self, outcome: Outcome) -> None:
        self._set_running(False)
        self.progress.setValue(1000)
        self.stage.setText(f"done: {len(outcome.plot.plants)} plants")
        self.show_results(outcome.plot, outcome.scene)

    def _failed(self, message: str) -> None:
        self._set_running(False)
        self.stage.setText(f"⚠ failed: {message.splitlines()[0]}")
        self.error.emit(message)

    def _cancelled(self) -> None:
        self._set_running(False)
        self.progress.setValue(0)
        self.stage.setText("cancelled")

    def _table_selected(self) -> None:
        if self._syncing_table:
            return
        selection = self.table.selectionModel()
        rows = selection.selectedRows()
        if not rows:
            return
        current = selection.currentIndex()  # the row clicked last, in a multiple selection
        chosen = current if current.isValid() and selection.isSelected(current) else rows[0]
        source = self.proxy.mapToSource(chosen)
        self.select_plant(self.plant_model.plants[source.row()].plant)
        plants = [self.plant_model.plants[self.proxy.mapToSource(i).row()].plant for i in rows]
        self.view3d.highlight(plants)  # every plant selected (a merge's), exactly its points
        self.map.highlight(plants)

    def _growth(self, trait: str) -> dict:  # type: ignore[type-arg]
        from fieldapp.results.history import growth_series

        return growth_series(self.history.observations, trait) if self.history.observations else {}

    def _report(self, action: str, call: object) -> None:
        try:
            call()  # type: ignore[operator]
        except FieldappError as error:
            self.stage.setText(f"⚠ {action}: {str(error).splitlines()[0]}")
            self.error.emit(f"{action}: {error}")

    def _ask_session(self) -> None:
        name = QtWidgets.QFileDialog.getExistingDirectory(self, "Session folder")
        if name:
            self._report("open session", lambda: self.open_session(Path(name)))

    def _ask_results(self) -> None:
        name = QtWidgets.QFileDialog.getExistingDirectory(self, "Results folder")
        if name:
            self._report("open results", lambda: self.open_results(Path(name)))

    def _run_clicked(self) -> None:
        self._report("reconstruct", self.reconstruct)

    def _record_clicked(self) -> None:
        if self.results is None:
            return
        plot = self.history.plot_name.text().strip()
        results = self.results
        self._report(
            "record", lambda: self.history.record(plot, results.session_folder, results.results_dir)
        )

    def _ask_export(self) -> None:
        name = QtWidgets.QFileDialog.getExistingDirectory(self, "Export into folder")
        if not name:
            return
        try:
            job = self.export_job(Path(name))
        except FieldappError as error:
            self.error.emit(f"export: {error}")
            return
        self.stage.setText("exporting…")
        self._export_jobs.run(
            job,
            lambda paths: self.stage.setText(f"exported {len(paths)} files to {name}"),
            lambda e: self.error.emit(f"export: {e}"),
        )
