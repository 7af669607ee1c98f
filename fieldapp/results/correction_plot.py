"""The plot being corrected: the automatic result's labelled cloud, rows and leaves, plants
measured again with the reconstruction's trait code, and the corrected files written."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fieldapp.errors import FormatError, Problem
from fieldapp.io.durable import write_bytes_durably
from fieldapp.recon.cloud import Cloud, width_points
from fieldapp.recon.organ_traits import PlantOrgans, foot_m, measure_organs
from fieldapp.recon.outputs import (
    LeafRow,
    PlantRow,
    PointLabels,
    csv_text,
    leaves_csv_text,
    ply_bytes,
    read_labelled_ply,
)
from fieldapp.recon.result import leaf_rows, organ_columns
from fieldapp.recon.settings import ReconstructionSettings
from fieldapp.recon.traits import measure_plant, robust_top_z_m
from fieldapp.results.organ_tables import read_table

PLANT_REQUIRED = ("plant", "x_m", "y_m", "height_cm", "width_cm", "points")
_INTEGERS = {"plant", "points", "leaf_count", "row", "column"}


@dataclass
class PlotState:
    """The labelled cloud (its labels are changed in place), the rows and leaves by plant,
    ``ground_m`` (K, 3) the automatic plants' local ground samples, whether organs are
    measured, whether ``plants.csv`` has the grid columns, and the plants corrected so far
    (``dirty``: to be measured again)."""

    cloud: Cloud
    labels: PointLabels
    rows: dict[int, PlantRow]
    leaves: dict[int, list[LeafRow]]
    ground_m: NDArray[np.float64]
    organs: bool
    grid: bool
    dirty: set[int] = field(default_factory=set)
    corrected: set[int] = field(default_factory=set)

    def centroids_xy_m(self) -> dict[int, NDArray[np.float64]]:
        """Per plant id, the centroid (2,) of its points in plan view."""
        ids = self.labels.plant_id
        kept = ids > 0
        if not kept.any():
            return {}
        counts = np.bincount(ids[kept])
        sums = [np.bincount(ids[kept], self.cloud.points[kept, a]) for a in (0, 1)]
        return {
            int(i): np.array([sums[0][i], sums[1][i]]) / counts[i] for i in np.flatnonzero(counts)
        }

    def members(self, plant: int) -> NDArray[np.intp]:
        return np.flatnonzero(self.labels.plant_id == plant)

    def plant_rows(self) -> list[PlantRow]:
        return [self.rows[i] for i in sorted(self.rows)]

    def leaf_rows(self) -> list[LeafRow]:
        return [leaf for i in sorted(self.leaves) for leaf in self.leaves[i]]


def load_state(folder: Path, settings: ReconstructionSettings) -> PlotState:
    """The automatic result of ``folder`` (its ``*.auto.*`` files), ready to be corrected."""
    cloud, labels = read_labelled_ply(folder / "cloud.auto.ply")
    if labels is None:
        raise FormatError([Problem(str(folder / "cloud.auto.ply"), "", "no plant_id per point")])
    table = read_table(folder / "plants.auto.csv", PLANT_REQUIRED)
    rows = {int(r["plant"]): _plant_row(r) for r in table}
    leaves: dict[int, list[LeafRow]] = {}
    organs = (folder / "leaves.auto.csv").is_file()
    if organs:
        path = folder / "leaves.auto.csv"
        for number, r in enumerate(read_table(path, ("plant_id", "leaf_id")), start=2):
            leaves.setdefault(int(r["plant_id"]), []).append(_leaf_row(r, path, number))
    grid = bool(table) and "row" in table[0]
    state = PlotState(cloud, _writable(labels), rows, leaves, np.zeros((0, 3)), organs, grid)
    state.ground_m = _ground_samples(state, settings)
    return state


def _writable(labels: PointLabels) -> PointLabels:
    return PointLabels(labels.plant_id.copy(), labels.organ.copy(), labels.leaf_id.copy())


def _plant_row(cells: dict[str, Any]) -> PlantRow:
    names = {f.name for f in fields(PlantRow)}
    values = {k: v for k, v in cells.items() if k in names}
    return PlantRow(
        **{k: int(v) if k in _INTEGERS and v is not None else v for k, v in values.items()}
    )


def _leaf_row(cells: dict[str, Any], path: Path, row: int) -> LeafRow:
    values: list[Any] = [cells.get(f.name) for f in fields(LeafRow)]
    blank = [f.name for f, v in zip(fields(LeafRow), values, strict=True) if v is None]
    if blank:
        raise FormatError([Problem(str(path), f"row {row} column {blank[0]}", "is blank")])
    return LeafRow(int(values[0]), int(values[1]), *(float(v) for v in values[2:]))


def _ground_samples(state: PlotState, settings: ReconstructionSettings) -> NDArray[np.float64]:
    """(K, 3) each automatic plant's base with its local ground z: its highest point less
    ``height_max_cm`` when measured, else its robust top less ``height_cm``."""
    samples = []
    p = settings.plants
    for plant, row in state.rows.items():
        points = state.cloud.points[state.members(plant)]
        if len(points) == 0:
            continue
        if row.height_max_cm is not None:
            ground = float(points[:, 2].max()) - row.height_max_cm / 100.0
        else:
            ground = (
                robust_top_z_m(points, p.top_support_points, p.top_support_radius_m)
                - row.height_cm / 100.0
            )
        samples.append((row.x_m, row.y_m, ground))
    return np.array(samples, np.float64).reshape(-1, 3)


def measure_again(state: PlotState, plant: int, settings: ReconstructionSettings) -> None:
    """Measure ``plant`` again from its points: traits, and organs when the result has them
    (blank when they cannot be measured); its row's grid cell is kept."""
    index = state.members(plant)
    cloud = state.cloud.select(index)
    points = cloud.points
    p = settings.plants
    traits = measure_plant(
        points,
        state.ground_m,
        p.base_slice_m,
        settings.ground.local_ground_radius_m,
        p.top_support_points,
        p.top_support_radius_m,
        width_points(cloud),  # as the reconstruction measured it
    )
    organs = _organs(points, foot_m(traits)) if state.organs else None
    state.labels.organ[index] = 0 if organs is None else organs.organs.organ
    state.labels.leaf_id[index] = 0 if organs is None else organs.organs.leaf_id
    old = state.rows.get(plant)
    state.rows[plant] = PlantRow(
        plant,
        traits.x_m,
        traits.y_m,
        traits.height_m * 100.0,
        traits.width_m * 100.0,
        traits.points,
        **organ_columns(organs),
        row=None if old is None else old.row,
        column=None if old is None else old.column,
    )
    state.leaves[plant] = [] if organs is None else leaf_rows(plant, organs)


def _organs(points_m: NDArray[np.float64], foot: NDArray[np.float64]) -> PlantOrgans | None:
    try:
        return measure_organs(points_m, foot)
    except (ValueError, np.linalg.LinAlgError):
        return None


def write_state(folder: Path, state: PlotState) -> None:
    """Rewrite ``plants.csv``, ``leaves.csv`` (when organs are measured), ``cloud.ply`` and
    ``plants/`` (stale plant clouds removed) from ``state``; a file that would not change is
    left as it is (each durable write waits for the disk)."""
    labels = state.labels
    _write_changed(folder / "cloud.ply", ply_bytes(state.cloud, labels))
    plants = folder / "plants"
    for old in plants.glob("*.ply") if plants.is_dir() else []:
        if old.stem.isdigit() and int(old.stem) not in state.rows:
            old.unlink()
    for plant in state.rows:
        index = state.members(plant)
        part = PointLabels(labels.plant_id[index], labels.organ[index], labels.leaf_id[index])
        _write_changed(plants / f"{plant}.ply", ply_bytes(state.cloud.select(index), part))
    _write_changed(folder / "plants.csv", csv_text(state.plant_rows(), grid=state.grid).encode())
    if state.organs:
        _write_changed(folder / "leaves.csv", leaves_csv_text(state.leaf_rows()).encode())


def _write_changed(path: Path, data: bytes) -> None:
    if path.is_file() and path.stat().st_size == len(data) and path.read_bytes() == data:
        return
    write_bytes_durably(path, data)
