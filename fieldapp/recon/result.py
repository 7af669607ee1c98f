"""What a reconstruction produces, and its ``report.json`` document."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from devices.geometry import Matrix4, invert, rotation_angle_deg
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.outputs import PlantRow
from fieldapp.recon.plants import Plant
from fieldapp.recon.register import StationRegistration

REPORT_FORMAT = "fieldapp-reconstruction-report/1"


@dataclass
class Reconstruction:
    """The plot reconstructed: plants (traits and points), the plant cloud in the field frame,
    how each station was placed, and the bookkeeping that goes into ``report.json``."""

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
            )
            for p in self.plants
        ]

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
