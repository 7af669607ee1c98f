"""The reconstruction's files, exactly as the session-format spec names them, written durably.

``plants.csv`` (plant,x_m,y_m,height_cm,width_cm,points, then the organ traits),
``leaves.csv`` (one row per leaf), ``cloud.ply`` (field frame, colour, and per point the plant,
organ and leaf when organs were measured), ``plants/<plant>.ply`` and ``report.json``; with
the run's provenance (:mod:`fieldapp.provenance`) in ``report.json`` and in ``provenance.json``
beside the CSVs (the spec's CSVs have no room for comment lines: every reader takes the first
line as the header).
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fieldapp.io import ply
from fieldapp.io.durable import json_bytes, write_files_durably
from fieldapp.recon.cloud import Cloud

if TYPE_CHECKING:
    from fieldapp.provenance import RunProvenance

PROVENANCE_FILE = "provenance.json"
OUTPUT_NAMES = ("plants.csv", "leaves.csv", "cloud.ply", "report.json", PROVENANCE_FILE, "plants")
"""What a results folder holds: any of them there means a reconstruction was written here."""

ORGAN_COLUMNS = [
    "leaf_count",
    "leaf_area_cm2",
    "stem_diameter_mm",
    "projected_area_cm2",
    "hull_volume_cm3",
    "height_max_cm",
    "height_p99_cm",
    "height_whorl_cm",
]
"""Organ traits (docs/TRAITS.md), after the paper's columns."""
GRID_COLUMNS = ["row", "column"]
"""Added to ``plants.csv`` after the traits when the session has a planting grid (1-based;
empty: a plant off the grid)."""

CSV_COLUMNS = ["plant", "x_m", "y_m", "height_cm", "width_cm", "points", *ORGAN_COLUMNS]

LEAF_COLUMNS = [
    "plant_id",
    "leaf_id",
    "length_cm",
    "max_width_cm",
    "area_cm2",
    "angle_from_stem_deg",
    "azimuth_deg",
    "insertion_height_cm",
]
"""``leaves.csv``, as the session-format spec names them."""

_PLY_BASE = [
    ("x", "<f4"),
    ("y", "<f4"),
    ("z", "<f4"),
    ("red", "u1"),
    ("green", "u1"),
    ("blue", "u1"),
]
_PLY_LABELS = [("plant_id", "<i4"), ("organ", "u1"), ("leaf_id", "u1")]
_PLY_MIXED = [("mixed", "u1")]


@dataclass(frozen=True)
class PlantRow:
    """One line of ``plants.csv``; positions in metres, traits in centimetres; the planting
    grid's row and column (1-based) when known."""

    plant: int
    x_m: float
    y_m: float
    height_cm: float
    width_cm: float
    points: int
    leaf_count: int | None = None
    leaf_area_cm2: float | None = None
    stem_diameter_mm: float | None = None
    projected_area_cm2: float | None = None
    hull_volume_cm3: float | None = None
    height_max_cm: float | None = None
    height_p99_cm: float | None = None
    height_whorl_cm: float | None = None
    row: int | None = None
    column: int | None = None


@dataclass(frozen=True)
class LeafRow:
    """One line of ``leaves.csv``: a leaf of plant ``plant_id``, ``leaf_id`` from the bottom."""

    plant_id: int
    leaf_id: int
    length_cm: float
    max_width_cm: float
    area_cm2: float
    angle_from_stem_deg: float
    azimuth_deg: float
    insertion_height_cm: float


@dataclass(frozen=True)
class PointLabels:
    """Per point of a cloud: ``plant_id`` (N,) int32 (0: none), ``organ`` (N,) uint8
    (:mod:`fieldapp.recon.organs` codes), ``leaf_id`` (N,) uint8 (0: not a leaf)."""

    plant_id: NDArray[np.int32]
    organ: NDArray[np.uint8]
    leaf_id: NDArray[np.uint8]


def ply_bytes(cloud: Cloud, labels: PointLabels | None = None) -> bytes:
    """A binary little-endian PLY of ``cloud``: float x, y, z, uchar red, green, blue; with
    ``labels``, int plant_id, uchar organ, uchar leaf_id; where the cloud's mixed pixels were
    looked for (:attr:`~fieldapp.recon.cloud.Cloud.mixed`), uchar mixed (1: a mixed pixel,
    which does not set its plant's width)."""
    fields = _PLY_BASE + (_PLY_LABELS if labels is not None else [])
    fields += _PLY_MIXED if cloud.mixed is not None else []
    vertices = np.empty(len(cloud), dtype=np.dtype(fields))
    for axis, name in enumerate("xyz"):
        vertices[name] = cloud.points[:, axis]
    for channel, name in enumerate(("red", "green", "blue")):
        vertices[name] = cloud.colors[:, channel]
    if labels is not None:
        for name, _ in _PLY_LABELS:
            vertices[name] = getattr(labels, name)
    if cloud.mixed is not None:
        vertices["mixed"] = cloud.mixed
    return ply.ply_bytes(vertices, ["fieldapp reconstruction, field frame, m"])


def read_ply(path: Path) -> Cloud:
    """Read a PLY written by :func:`ply_bytes` (for tests and tools)."""
    return read_labelled_ply(path)[0]


def read_labelled_ply(path: Path) -> tuple[Cloud, PointLabels | None]:
    """Read a PLY written by :func:`ply_bytes`: the cloud and its labels when it has them.
    Raises :class:`~fieldapp.io.ply.PlyError` (a ValueError) naming the file."""
    vertices = ply.read_ply(path)
    colors = ply.colors_of(vertices)
    if colors is None:
        raise ply.PlyError(f"{path}: PLY vertices have no red, green, blue")
    labels = None
    if all(name in (vertices.dtype.names or ()) for name, _ in _PLY_LABELS):
        labels = PointLabels(
            vertices["plant_id"].astype(np.int32),
            vertices["organ"].astype(np.uint8),
            vertices["leaf_id"].astype(np.uint8),
        )
    mixed = vertices["mixed"] != 0 if "mixed" in (vertices.dtype.names or ()) else None
    return Cloud(ply.points_of(vertices, str(path)), colors, mixed), labels


def read_results_cloud(folder: Path) -> tuple[Cloud, PointLabels]:
    """``cloud.ply`` of a results folder with its per-point labels; a cloud written without
    them (organs not measured, an imported cloud) gets each point's plant from the
    ``plants/<plant>.ply`` that holds it (:func:`plant_of_points`), organ and leaf 0. Raises
    FileNotFoundError, or :class:`~fieldapp.io.ply.PlyError` (a ValueError), naming the file."""
    path = folder / "cloud.ply"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: file is missing")
    cloud, labels = read_labelled_ply(path)
    if labels is not None:
        return cloud, labels
    plant_clouds = {
        int(plant_path.stem): read_ply(plant_path)
        for plant_path in sorted((folder / "plants").glob("*.ply"))
        if plant_path.stem.isdigit()
    }
    none = np.zeros(len(cloud), np.uint8)
    return cloud, PointLabels(plant_of_points(cloud, plant_clouds), none, none.copy())


def plant_of_points(cloud: Cloud, plant_clouds: dict[int, Cloud]) -> NDArray[np.int32]:
    """(N,) for each point of ``cloud`` the plant whose cloud holds the very same point (the
    files keep the same float32 coordinates), 0 for a point of no plant. For a cloud written
    without per-point labels (organs not measured)."""
    found = np.zeros(len(cloud), np.int32)
    if len(cloud) == 0 or not plant_clouds:
        return found
    keys = _point_keys(cloud.points)
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    for plant, plant_cloud in plant_clouds.items():
        if len(plant_cloud) == 0:
            continue
        wanted = _point_keys(plant_cloud.points)
        where = np.clip(np.searchsorted(sorted_keys, wanted), 0, len(keys) - 1)
        hit = sorted_keys[where] == wanted
        found[order[where[hit]]] = plant
    return found


def _point_keys(points_m: NDArray[np.float64]) -> NDArray[np.void]:
    """(N,) one sortable key per point: its float32 coordinates' bytes."""
    exact = np.ascontiguousarray(points_m, np.float32)
    return exact.view(np.dtype((np.void, 12))).ravel()


def csv_text(rows: list[PlantRow], grid: bool | None = None) -> str:
    """``plants.csv``; with ``row`` and ``column`` when ``grid`` (default: when a row has one)."""
    with_grid = any(r.row is not None for r in rows) if grid is None else grid
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(CSV_COLUMNS + (GRID_COLUMNS if with_grid else []))
    for row in rows:
        cells: list[object] = [
            row.plant,
            f"{row.x_m:.4f}",
            f"{row.y_m:.4f}",
            f"{row.height_cm:.2f}",
            f"{row.width_cm:.2f}",
            row.points,
            *(_optional(getattr(row, name)) for name in ORGAN_COLUMNS),
        ]
        if with_grid:
            cells += ["" if row.row is None else row.row, "" if row.column is None else row.column]
        writer.writerow(cells)
    return buffer.getvalue()


def _optional(value: float | None) -> str:
    """A blank cell for a trait not measured, an integer as is, else two decimals."""
    if value is None:
        return ""
    return str(value) if isinstance(value, int) else f"{value:.2f}"


def leaves_csv_text(rows: list[LeafRow]) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(LEAF_COLUMNS)
    for row in rows:
        writer.writerow(
            [row.plant_id, row.leaf_id] + [f"{getattr(row, name):.2f}" for name in LEAF_COLUMNS[2:]]
        )
    return buffer.getvalue()


def write_outputs(
    folder: Path,
    rows: list[PlantRow],
    cloud: Cloud,
    plant_clouds: dict[int, Cloud],
    report: dict[str, Any],
    leaves: list[LeafRow] | None = None,
    labels: PointLabels | None = None,
    plant_labels: dict[int, PointLabels] | None = None,
    provenance: RunProvenance | None = None,
) -> list[Path]:
    """Write every output file into ``folder`` (created); returns the paths written. Plant
    clouds left in ``plants/`` by an earlier run with more plants are removed. ``leaves``
    (``leaves.csv``, written when given) and the per-point ``labels`` of ``cloud`` and
    ``plant_labels`` of each plant cloud come from the organ step. ``provenance`` (given by a
    new reconstruction, not by a re-export) goes into ``report.json`` (``provenance``,
    ``settings``, ``software_version``), and then a ``leaves.csv`` an earlier run left is
    removed when this run has none; ``provenance.json`` is written whenever the report has a
    provenance (also when results are exported again)."""
    if provenance is not None:
        report = report | {
            "provenance": provenance.document,
            "settings": provenance.settings,
            "software_version": provenance.document["software"]["version"],
        }
    stale = folder / "plants"
    if stale.is_dir():
        for old in stale.glob("*.ply"):
            if old.stem.isdigit() and int(old.stem) not in plant_clouds:
                old.unlink()
    files = {folder / "cloud.ply": ply_bytes(cloud, labels)}
    for plant, plant_cloud in plant_clouds.items():
        plant_ply = ply_bytes(plant_cloud, (plant_labels or {}).get(plant))
        files[folder / "plants" / f"{plant}.ply"] = plant_ply
    files[folder / "plants.csv"] = csv_text(rows).encode("utf-8")
    if leaves is not None:
        files[folder / "leaves.csv"] = leaves_csv_text(leaves).encode("utf-8")
    elif provenance is not None and (folder / "leaves.csv").exists():
        (folder / "leaves.csv").unlink()  # an earlier run's leaves are not this run's plants
    if isinstance(report.get("provenance"), dict):
        files[folder / PROVENANCE_FILE] = json_bytes(report["provenance"])
    files[folder / "report.json"] = json_bytes(report)  # last: the run's record
    write_files_durably(files)
    return list(files)


def existing_outputs(folder: Path) -> list[Path]:
    """The reconstruction outputs already in ``folder`` (empty when it holds none)."""
    return [folder / name for name in OUTPUT_NAMES if (folder / name).exists()]
