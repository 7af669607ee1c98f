"""What a reconstruction produces, and its ``report.json`` document."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from devices.geometry import Matrix4, invert, rotation_angle_deg
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.outputs import PlantRow
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
    search: PlantSearch | None = None
    frame: str = "field"
    T_map_field: Matrix4 | None = None
    expected_plants: int | None = None
    flag_ambiguous_share: float = 0.05

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
                row=p.grid_cell[0] if p.grid_cell else None,
                column=p.grid_cell[1] if p.grid_cell else None,
            )
            for p in self.plants
        ]

    def plant_report(self) -> dict[str, Any]:
        """How the plants were found: from stems or clusters, ambiguous shares (flagged above
        ``flag_ambiguous_share``), splits and merges, grid cells missing and plants extra."""
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
                }
                for p in self.plants
            ],
            "splits": [{"plants": ids} for ids in search.splits],
            "merges": search.merges,
            "missing_cells": [list(cell) for cell in search.missing_cells],
            "extra_plants": search.extra_plants,
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
            "exg_thresholds": {str(s): round(t, 4) for s, t in sorted(self.exg_thresholds.items())},
            "timings_s": {name: round(t, 4) for name, t in self.timings_s.items()},
            "cpu_s": {name: round(t, 4) for name, t in self.cpu_s.items()},
            "warnings": self.warnings,
        }


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
    }


def _finite_or_none(value: float | None) -> float | None:
    return value if value is not None and math.isfinite(value) else None
