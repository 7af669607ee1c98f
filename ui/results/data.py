"""What the results panel shows, from a reconstruction just run or a results folder on disk:
the plants' traits, the global cloud and each plant's cloud (field frame), which plant each
point of the global cloud belongs to, ``report.json``."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fieldapp.errors import FormatError, Problem
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.outputs import plant_of_points, read_labelled_ply
from fieldapp.results.files import PlantRecord, read_plants_csv, read_report
from fieldapp.results.organ_tables import read_table


@dataclass
class PlotResults:
    """One reconstructed plot. ``cloud``: the plants' points (field frame, metres)."""

    session_id: str
    results_dir: Path
    plants: list[PlantRecord]
    cloud: Cloud
    plant_clouds: dict[int, Cloud]
    report: dict[str, Any]
    session_folder: Path | None = None
    warnings: list[str] = field(default_factory=list)
    leaves: dict[int, list[dict[str, Any]]] = field(default_factory=dict)
    """Per plant, its ``leaves.csv`` rows from the bottom (empty: organs not measured)."""
    point_plants: NDArray[np.int32] | None = None
    """(N,) the plant of each point of ``cloud`` (0: none), as the reconstruction or the
    corrections assigned it; ``None``: not known (see :func:`plant_of_points`)."""

    def plant_of_point(self) -> NDArray[np.int32]:
        """(N,) the plant of each point of ``cloud``: ``point_plants``, else found exactly
        from the plant clouds."""
        if self.point_plants is None:
            self.point_plants = plant_of_points(self.cloud, self.plant_clouds)
        return self.point_plants

    def plant(self, plant_id: int) -> PlantRecord:
        for record in self.plants:
            if record.plant == plant_id:
                return record
        raise KeyError(plant_id)

    def top_m(self, plant_id: int) -> NDArray[np.float64]:
        """(3,) the point above the plant's base at the height of its highest point."""
        record = self.plant(plant_id)
        cloud = self.plant_clouds.get(plant_id)
        z = float(cloud.points[:, 2].max()) if cloud is not None and len(cloud) else 0.0
        return np.array([record.x_m, record.y_m, z])


def load_results_dir(folder: Path) -> PlotResults:
    """A results folder written by ``fieldapp reconstruct``; raises :class:`FormatError`."""
    if not (folder / "plants.csv").is_file():
        raise FormatError([Problem(str(folder), "", "no plants.csv: not a results folder")])
    plants = read_plants_csv(folder / "plants.csv")
    report = read_report(folder / "report.json")
    cloud, point_plants = _read_labelled_cloud(folder / "cloud.ply")
    plant_clouds = {}
    for record in plants:
        path = folder / "plants" / f"{record.plant}.ply"
        if path.is_file():
            plant_clouds[record.plant] = _read_cloud(path)
    warnings = [str(w) for w in report.get("warnings", []) or []]
    leaves: dict[int, list[dict[str, Any]]] = {}
    if (folder / "leaves.csv").is_file():
        for row in read_table(folder / "leaves.csv", ("plant_id", "leaf_id")):
            leaves.setdefault(int(row["plant_id"]), []).append(row)
    return PlotResults(
        str(report.get("session", folder.name)),
        folder,
        plants,
        cloud,
        plant_clouds,
        report,
        warnings=warnings,
        leaves=leaves,
        point_plants=point_plants,
    )


def _read_cloud(path: Path) -> Cloud:
    return _read_labelled_cloud(path)[0]


def _read_labelled_cloud(path: Path) -> tuple[Cloud, NDArray[np.int32] | None]:
    """The cloud of ``path`` and its points' plants when the file has them."""
    try:
        cloud, labels = read_labelled_ply(path)
        return cloud, None if labels is None else labels.plant_id
    except FileNotFoundError:
        raise FormatError([Problem(str(path), "", "file is missing")]) from None
    except (ValueError, OSError) as error:
        raise FormatError([Problem(str(path), "", f"not a fieldapp PLY ({error})")]) from None
