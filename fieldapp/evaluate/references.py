"""Reference measurements to evaluate the traits against, paired with the algorithm's plants:
hand measurements (``manual.csv``, by plant id) or a simulator's ``truth.json`` (by position).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from fieldapp.io.jsonfile import load_model
from fieldapp.results.files import ManualRecord, PlantRecord
from fieldapp.results.identity import match_positions


class _Model(BaseModel):
    model_config = ConfigDict(extra="allow")


class TruthPlant(_Model):
    name: str
    x_m: float = Field(allow_inf_nan=False)
    y_m: float = Field(allow_inf_nan=False)
    height_cm: float = Field(ge=0.0, allow_inf_nan=False)
    width_cm: float = Field(ge=0.0, allow_inf_nan=False)
    map_x_m: float | None = Field(default=None, allow_inf_nan=False)
    map_y_m: float | None = Field(default=None, allow_inf_nan=False)

    @property
    def plot_xy_m(self) -> tuple[float, float]:
        """Where ``plants.csv`` reports it: the map frame when the truth has it (simulated
        sessions carry base poses, so plants are reported in the map frame)."""
        if self.map_x_m is not None and self.map_y_m is not None:
            return self.map_x_m, self.map_y_m
        return self.x_m, self.y_m


class TruthSphere(_Model):
    name: str
    x_m: float = Field(allow_inf_nan=False)
    y_m: float = Field(allow_inf_nan=False)
    z_m: float = Field(allow_inf_nan=False)
    diameter_mm: float = Field(gt=0.0, allow_inf_nan=False)


class Truth(_Model):
    """The parts of a simulator's ``truth.json`` (``fieldapp-sim-truth/1``) used here."""

    format: str = Field(pattern=r"^fieldapp-sim-truth/")
    plants: list[TruthPlant] = Field(default_factory=list)
    spheres: list[TruthSphere] = Field(default_factory=list)


def load_truth(path: Path) -> Truth:
    """Read a ``truth.json``; raises :class:`~fieldapp.errors.FormatError` naming bad fields."""
    return load_model(path, Truth)


@dataclass(frozen=True)
class TraitPair:
    """A plant as the algorithm measured it and its reference (``None``: not measured)."""

    plant: int
    reference: str
    height_cm: float
    width_cm: float
    reference_height_cm: float | None
    reference_width_cm: float | None
    distance_m: float | None = None


@dataclass
class Pairing:
    """Pairs, and what found no partner on either side."""

    pairs: list[TraitPair]
    unmatched_plants: list[int] = field(default_factory=list)
    unmatched_references: list[str] = field(default_factory=list)

    def warnings(self) -> list[str]:
        lines = []
        if self.unmatched_plants:
            ids = ", ".join(str(p) for p in self.unmatched_plants)
            lines.append(f"{len(self.unmatched_plants)} plants without a reference: {ids}")
        if self.unmatched_references:
            names = ", ".join(self.unmatched_references)
            lines.append(f"{len(self.unmatched_references)} references without a plant: {names}")
        return lines


def pair_with_manual(plants: list[PlantRecord], manual: list[ManualRecord]) -> Pairing:
    """Pairs by plant id (the ``plant`` column of both files)."""
    by_id = {m.plant: m for m in manual}
    pairs = [
        TraitPair(p.plant, str(p.plant), p.height_cm, p.width_cm, m.height_cm, m.width_cm)
        for p in plants
        if (m := by_id.get(p.plant)) is not None
    ]
    ids = {p.plant for p in plants}
    return Pairing(
        pairs,
        [p.plant for p in plants if p.plant not in by_id],
        [str(m.plant) for m in manual if m.plant not in ids],
    )


def pair_with_truth(
    plants: list[PlantRecord], truth: list[TruthPlant], max_distance_m: float
) -> Pairing:
    """Pairs by base position in the field frame (one-to-one, within ``max_distance_m``)."""
    truth_xy = np.array([t.plot_xy_m for t in truth], np.float64).reshape(-1, 2)
    plant_xy = np.array([[p.x_m, p.y_m] for p in plants], np.float64).reshape(-1, 2)
    matches = match_positions(truth_xy, plant_xy, max_distance_m)
    pairs = []
    for plant, match in zip(plants, matches, strict=True):
        if match is None:
            continue
        t = truth[match]
        distance = float(np.hypot(plant.x_m - t.plot_xy_m[0], plant.y_m - t.plot_xy_m[1]))
        pairs.append(
            TraitPair(
                plant.plant,
                t.name,
                plant.height_cm,
                plant.width_cm,
                t.height_cm,
                t.width_cm,
                distance,
            )
        )
    matched = {m for m in matches if m is not None}
    return Pairing(
        pairs,
        [p.plant for p, m in zip(plants, matches, strict=True) if m is None],
        [t.name for i, t in enumerate(truth) if i not in matched],
    )
