"""The reconstruction's files, exactly as the session-format spec names them, written durably.

``plants.csv`` (plant,x_m,y_m,height_cm,width_cm,points), ``cloud.ply`` (field frame, colour),
``plants/<plant>.ply`` and ``report.json``.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fieldapp.io.durable import write_bytes_durably, write_json_durably
from fieldapp.recon.cloud import Cloud

CSV_COLUMNS = ["plant", "x_m", "y_m", "height_cm", "width_cm", "points"]
GRID_COLUMNS = ["row", "column"]
"""Added to ``plants.csv`` when the session has a planting grid (1-based; empty: extra plant)."""

_PLY_VERTEX = np.dtype(
    [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")]
)


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
    row: int | None = None
    column: int | None = None


def ply_bytes(cloud: Cloud) -> bytes:
    """A binary little-endian PLY of ``cloud``: float x, y, z and uchar red, green, blue."""
    vertices = np.empty(len(cloud), dtype=_PLY_VERTEX)
    for axis, name in enumerate("xyz"):
        vertices[name] = cloud.points[:, axis]
    for channel, name in enumerate(("red", "green", "blue")):
        vertices[name] = cloud.colors[:, channel]
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment fieldapp reconstruction, field frame, m\n"
        f"element vertex {len(cloud)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
    )
    return header.encode("ascii") + vertices.tobytes()


def read_ply(path: Path) -> Cloud:
    """Read a PLY written by :func:`ply_bytes` (for tests and tools)."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    vertices = np.frombuffer(data[end:], dtype=_PLY_VERTEX)
    points = np.stack([vertices[a] for a in "xyz"], axis=1).astype(np.float64)
    colors = np.stack([vertices[c] for c in ("red", "green", "blue")], axis=1)
    return Cloud(points, colors.astype(np.uint8))


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
        ]
        if with_grid:
            cells += ["" if row.row is None else row.row, "" if row.column is None else row.column]
        writer.writerow(cells)
    return buffer.getvalue()


def write_outputs(
    folder: Path,
    rows: list[PlantRow],
    cloud: Cloud,
    plant_clouds: dict[int, Cloud],
    report: dict[str, Any],
) -> list[Path]:
    """Write every output file into ``folder`` (created); returns the paths written. Plant
    clouds left in ``plants/`` by an earlier run with more plants are removed."""
    written = [folder / "cloud.ply"]
    stale = folder / "plants"
    if stale.is_dir():
        for old in stale.glob("*.ply"):
            if old.stem.isdigit() and int(old.stem) not in plant_clouds:
                old.unlink()
    write_bytes_durably(written[0], ply_bytes(cloud))
    for plant, plant_cloud in plant_clouds.items():
        path = folder / "plants" / f"{plant}.ply"
        write_bytes_durably(path, ply_bytes(plant_cloud))
        written.append(path)
    write_bytes_durably(folder / "plants.csv", csv_text(rows).encode("utf-8"))
    write_json_durably(folder / "report.json", report)
    return [*written, folder / "plants.csv", folder / "report.json"]
