"""What a reconstruction produces, and its ``report.json`` document."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from devices.geometry import Matrix4, invert, rotation_angle_deg
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.organ_traits import PlantOrgans
from fieldapp.recon.outputs import LeafRow, PlantRow, PointLabels
from fieldapp.recon.plants import Plant, PlantSearch
from fieldapp.recon.register import StationRegistration

REPORT_FORMAT = "fieldapp-reconstruction-report/1"


@dataclass
class Reconstruction:
    """The plot reconstructed: plants (traits and points), the plant cloud in the field frame,
    how each station was placed, and the bookkeeping that goes into ``report.json``.

    ``frame`` is ``"map"`` when the field frame's x and y are the map's (``T_map_field`` took
    the levelled frame onto it), ``"field"`` when the session had no map poses."""

    session_id: str
    reference: int
    plants: list[Plant]
    cloud: Cloud
    registrations: dict[int, StationRegistration]
    T_field_reference: Matrix4
    kept: dict[str, int]
    exg_thresholds: dict[int, float]
    timings_s: dict[str, float]
    cpu_s: dict[str, float]
    warnings: list[str]
    organs: dict[int, PlantOrgans] = field(default_factory=dict)
    """The organ step's result per plant id (empty when organs were not measured)."""
    separation: dict[int, str] = field(default_factory=dict)
    """Per station, how its plants were told from the soil (colour, or geometry and why)."""
    colour_offsets: dict[int, tuple[int, int]] = field(default_factory=dict)
    """Per station whose colour told it, how far (dx, dy pixels) its colour was found off its
    depth and moved back (``recon/colour_offset.py``); (0, 0): in place."""
    turntable: dict[str, Any] | None = None
    """A plant-on-turntable session: the working volume and how the views were placed."""

    def separation_lines(self) -> list[str]:
        """One line per way of separating plants used, with its stations."""
        by_line: dict[str, list[int]] = {}
        for station, line in sorted(self.separation.items()):
            by_line.setdefault(line, []).append(station)
        return [
            f"{line} (station{'s' if len(s) > 1 else ''} {', '.join(map(str, s))})"
            for line, s in by_line.items()
        ]

    search: PlantSearch | None = None
    frame: str = "field"
    T_map_field: Matrix4 | None = None
    expected_plants: int | None = None
    flag_ambiguous_share: float = 0.05
    crop_radius_m: float | None = None
    """The back-projection's crop radius used (scaled to the rig, ``backproject.rig_crop``)."""
    cautions: dict[int, tuple[str, ...]] = field(default_factory=dict)
    """Per plant id, why its traits are less sure than the others' (``recon/coverage.py``: the
    captures did not cover it as planned, its top lies where the views stop seeing)."""

    def rows(self) -> list[PlantRow]:
        """The lines of ``plants.csv``."""
        return [
            PlantRow(
                plant=p.id,
                x_m=p.traits.x_m,
                y_m=p.traits.y_m,
                height_cm=p.traits.height_m * 100.0,
                width_cm=p.traits.width_m * 100.0,
                points=p.traits.points,
                **organ_columns(self.organs.get(p.id)),
                row=p.grid_cell[0] if p.grid_cell else None,
                column=p.grid_cell[1] if p.grid_cell else None,
            )
            for p in self.plants
        ]

    def leaf_rows(self) -> list[LeafRow]:
        """The lines of ``leaves.csv``: every leaf of every plant, plant by plant."""
        return [
            row
            for plant_id, organs in sorted(self.organs.items())
            for row in leaf_rows(plant_id, organs)
        ]

    def plant_labels(self) -> dict[int, PointLabels]:
        """Per plant id, the plant, organ and leaf of each of its points."""
        return {
            p.id: PointLabels(
                np.full(len(p.cloud), p.id, np.int32),
                self.organs[p.id].organs.organ,
                self.organs[p.id].organs.leaf_id,
            )
            for p in self.plants
            if p.id in self.organs
        }

    def cloud_labels(self) -> PointLabels:
        """The plant, organ and leaf of each point of :attr:`cloud` (0 where it is in no
        plant): a plant's points are copies of the cloud's, found by their coordinates' bits
        (and, for any not found so, by position within 0.1 micrometre)."""
        n = len(self.cloud)
        labels = PointLabels(np.zeros(n, np.int32), np.zeros(n, np.uint8), np.zeros(n, np.uint8))
        if n == 0 or not self.plants:
            return labels
        by_id = {p.id: p for p in self.plants}
        rows = RowFinder(self.cloud.points)
        for plant_id, plant_labels in self.plant_labels().items():
            index = rows.find(by_id[plant_id].cloud.points)
            found = index >= 0
            labels.plant_id[index[found]] = plant_id
            labels.organ[index[found]] = plant_labels.organ[found]
            labels.leaf_id[index[found]] = plant_labels.leaf_id[found]
        return labels

    def output_extras(self) -> dict[str, Any]:
        """The organ step's outputs as :func:`fieldapp.recon.outputs.write_outputs` takes them
        (nothing when organs were not measured)."""
        if not self.organs:
            return {}
        return {
            "leaves": self.leaf_rows(),
            "labels": self.cloud_labels(),
            "plant_labels": self.plant_labels(),
        }

    def plant_report(self) -> dict[str, Any]:
        """How the plants were found: from stems or clusters, ambiguous shares (flagged above
        ``flag_ambiguous_share``), each plant's cautions, splits and merges, grid cells missing
        and plants extra, how the grid was fitted to the stems."""
        search = self.search or PlantSearch(self.plants)
        return {
            "method": "stems, geodesic assignment; density clusters where no stem is seen",
            "expected": self.expected_plants,
            "plants": [
                {
                    "plant": p.id,
                    "from_stem": p.from_stem,
                    "ambiguous_share": round(p.ambiguous_share, 4),
                    "flagged": p.ambiguous_share > self.flag_ambiguous_share,
                    "grid_cell": list(p.grid_cell) if p.grid_cell else None,
                    "cautions": list(self.cautions.get(p.id, ())),
                }
                for p in self.plants
            ],
            "splits": [{"plants": ids} for ids in search.splits],
            "merges": search.merges,
            "missing_cells": [list(cell) for cell in search.missing_cells],
            "unseen_cells": [list(cell) for cell in search.unseen_cells],
            "extra_plants": search.extra_plants,
            "grid_fit": None
            if search.grid_fit is None
            else {
                "stems": search.grid_fit.stems,
                "moved_m": round(search.grid_fit.moved_m, 4),
                "turned_deg": round(search.grid_fit.turned_deg, 3),
                "applied": search.grid_fit.applied,
            },
        }

    def T_reference_station(self, station: int) -> Matrix4:
        """Where ``station`` (view 0) ended up relative to the anchoring station."""
        return invert(self.T_field_reference) @ self.registrations[station].T_field_station

    def report(self) -> dict[str, Any]:
        """The ``report.json`` document."""
        return {
            "format": REPORT_FORMAT,
            "session": self.session_id,
            "reference_station": self.reference,
            "plants": len(self.plants),
            "frame": self.frame,
            "T_map_field": None if self.T_map_field is None else self.T_map_field.tolist(),
            "plant_search": self.plant_report(),
            "stations": {str(s): _station_entry(r) for s, r in sorted(self.registrations.items())},
            "points_kept": self.kept,
            "crop_radius_m": self.crop_radius_m,
            "plant_separation": {str(s): line for s, line in sorted(self.separation.items())},
            "exg_thresholds": {str(s): round(t, 4) for s, t in sorted(self.exg_thresholds.items())},
            "colour_offset_px": {str(s): list(o) for s, o in sorted(self.colour_offsets.items())},
            "timings_s": {name: round(t, 4) for name, t in self.timings_s.items()},
            "cpu_s": {name: round(t, 4) for name, t in self.cpu_s.items()},
            "warnings": self.warnings,
        } | ({"turntable": self.turntable} if self.turntable is not None else {})


class RowFinder:
    """Finds points (M, 3) among ``points`` (N, 3) float64: bit for bit through one sorted
    hash of the rows (a k-d tree of the whole cloud cost more than the rest of the outputs),
    within 0.1 micrometre through a k-d tree for those not found so."""

    def __init__(self, points: NDArray[np.float64]) -> None:
        self.points = points
        keys = _row_keys(points)
        self.order = np.argsort(keys)
        self.sorted_keys = keys[self.order]
        self._tree: cKDTree | None = None

    def find(self, queries: NDArray[np.float64]) -> NDArray[np.intp]:
        """(M,) the index of each query point in ``points``, -1 where it is not there."""
        if len(queries) == 0:
            return np.zeros(0, dtype=np.intp)
        keys = _row_keys(queries)
        at = np.minimum(np.searchsorted(self.sorted_keys, keys), len(self.order) - 1)
        index = self.order[at]
        same = (self.sorted_keys[at] == keys) & np.all(self.points[index] == queries, axis=1)
        missing = np.flatnonzero(~same)
        if len(missing):
            self._tree = self._tree or cKDTree(self.points)
            distance, nearest = self._tree.query(queries[missing], distance_upper_bound=1e-7)
            index[missing] = np.where(np.isfinite(distance), nearest, -1)
        return index


def _row_keys(points: NDArray[np.float64]) -> NDArray[np.uint64]:
    """(N,) a 64-bit hash of each row's three coordinates' bits (equal rows, equal keys)."""
    bits = np.ascontiguousarray(points, dtype=np.float64).view(np.uint64)
    mixed = bits * np.array([0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9], np.uint64)
    return mixed[:, 0] ^ (mixed[:, 1] >> np.uint64(7)) ^ (mixed[:, 2] << np.uint64(5))  # type: ignore[no-any-return]


def leaf_rows(plant_id: int, organs: PlantOrgans) -> list[LeafRow]:
    """The ``leaves.csv`` lines of one plant, in their units (also used by manual corrections)."""
    return [
        LeafRow(
            plant_id=plant_id,
            leaf_id=leaf.leaf_id,
            length_cm=100.0 * leaf.length_m,
            max_width_cm=100.0 * leaf.max_width_m,
            area_cm2=1e4 * leaf.area_m2,
            angle_from_stem_deg=leaf.angle_from_stem_deg,
            azimuth_deg=leaf.azimuth_deg,
            insertion_height_cm=100.0 * leaf.insertion_height_m,
        )
        for leaf in organs.leaves
    ]


def organ_columns(organs: PlantOrgans | None) -> dict[str, Any]:
    """The organ columns of a plant's ``plants.csv`` row, in their units (``{}``: all blank;
    also used by manual corrections)."""
    if organs is None:
        return {}
    return {
        "leaf_count": organs.leaf_count,
        "leaf_area_cm2": 1e4 * organs.leaf_area_m2,
        "stem_diameter_mm": _scaled(organs.stem_diameter_m, 1000.0),
        "projected_area_cm2": 1e4 * organs.projected_area_m2,
        "hull_volume_cm3": 1e6 * organs.hull_volume_m3,
        "height_max_cm": 100.0 * organs.height_max_m,
        "height_p99_cm": 100.0 * organs.height_p99_m,
        "height_whorl_cm": _scaled(organs.height_whorl_m, 100.0),
    }


def _scaled(value: float | None, factor: float) -> float | None:
    return None if value is None else factor * value


def _station_entry(registration: StationRegistration) -> dict[str, Any]:
    correction = registration.T_correction
    return {
        "T_field_station": registration.T_field_station.tolist(),
        "icp_accepted": registration.accepted,
        "icp_fitness": _finite_or_none(registration.fitness),
        "icp_rmse_m": _finite_or_none(registration.rmse_m),
        "correction": correction.tolist(),
        "correction_rotation_deg": round(rotation_angle_deg(correction[:3, :3]), 4),
        "neighbours": registration.neighbours,
        "message": registration.message,
        "verdict": registration.verdict,
        "uncertainty_mm": _rounded(registration.uncertainty_m, 1000),
        "uncertainty_deg": _rounded(registration.uncertainty_deg, 1),
        "correction_limit_mm": _rounded(registration.limit_m, 1000),
        "correction_limit_deg": _rounded(registration.limit_deg, 1),
    }


def _rounded(value: float | None, scale: float) -> float | None:
    finite = _finite_or_none(value)
    return None if finite is None else round(finite * scale, 4)


def _finite_or_none(value: float | None) -> float | None:
    return value if value is not None and math.isfinite(value) else None
