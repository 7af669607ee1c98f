"""Organ traits against references: leaves paired within each paired plant, then agreement of
every leaf trait, of the plants' leaf count, leaf area and stem diameter (docs/EVALUATION.md).

Leaves are paired by where they leave the stem: azimuth and insertion height (Hungarian
assignment on a cost of both, a pair farther than :data:`MAX_LEAF_COST` is no pair). A leaf
found with no reference is ``extra``; a reference leaf not found is ``missed``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from fieldapp.evaluate.metrics import Agreement, agreement
from fieldapp.results.organ_tables import LEAF_TRAITS
from fieldapp.results.organ_tables import PLANT_ORGAN_TRAITS as PLANT_TRAITS

UNITS = {
    "length_cm": "cm",
    "max_width_cm": "cm",
    "area_cm2": "cm²",
    "angle_from_stem_deg": "°",
    "azimuth_deg": "°",
    "insertion_height_cm": "cm",
    "leaf_count": "leaves",
    "leaf_area_cm2": "cm²",
    "stem_diameter_mm": "mm",
}
"""The unit of every organ trait, for tables and figures."""

AZIMUTH_SCALE_DEG = 45.0
HEIGHT_SCALE_CM = 2.0
MAX_LEAF_COST = 2.0
"""Pairing cost: azimuth difference / 45 degrees + insertion height difference / 2 cm."""


def azimuth_difference_deg(a: float, b: float) -> float:
    """``a - b`` wrapped into [-180, 180)."""
    return float((a - b + 180.0) % 360.0 - 180.0)


def pair_leaves(
    found: list[dict[str, Any]], reference: list[dict[str, Any]]
) -> list[tuple[int, int]]:
    """Pairs (index in ``found``, index in ``reference``) of leaves (dicts with at least
    ``azimuth_deg`` and ``insertion_height_cm``)."""
    from scipy.optimize import linear_sum_assignment  # SciPy loads when first used

    if not found or not reference:
        return []
    cost = np.array(
        [
            [
                abs(azimuth_difference_deg(f["azimuth_deg"], r["azimuth_deg"])) / AZIMUTH_SCALE_DEG
                + abs(f["insertion_height_cm"] - r["insertion_height_cm"]) / HEIGHT_SCALE_CM
                for r in reference
            ]
            for f in found
        ]
    )
    rows, cols = linear_sum_assignment(cost)
    return [
        (int(i), int(j)) for i, j in zip(rows, cols, strict=True) if cost[i, j] <= MAX_LEAF_COST
    ]


def pair_leaves_by_id(
    found: list[dict[str, Any]], reference: list[dict[str, Any]]
) -> list[tuple[int, int]]:
    """Pairs of leaves with the same ``leaf_id`` (numbered from the bottom): how hand
    measurements, which rarely note azimuths, are paired."""
    index = {int(leaf["leaf_id"]): j for j, leaf in enumerate(reference)}
    return [
        (i, index[int(leaf["leaf_id"])])
        for i, leaf in enumerate(found)
        if int(leaf["leaf_id"]) in index
    ]


@dataclass(frozen=True)
class PlantOrganPair:
    """One plant and its reference: the plant-level values and the paired leaves."""

    plant: int
    reference: str
    found: dict[str, Any]
    expected: dict[str, Any]
    leaf_pairs: list[tuple[dict[str, Any], dict[str, Any]]]
    extra: int
    missed: int


def pair_plant(
    plant: int,
    reference: str,
    found: dict[str, Any],
    found_leaves: list[dict[str, Any]],
    expected: dict[str, Any],
    by_id: bool = False,
) -> PlantOrganPair:
    """Pair ``found_leaves`` with the reference's ``expected["leaves"]``: by where they leave
    the stem, or ``by_id`` by their numbers from the bottom."""
    reference_leaves = list(expected.get("leaves") or [])
    pairing = pair_leaves_by_id if by_id else pair_leaves
    pairs = pairing(found_leaves, reference_leaves)
    return PlantOrganPair(
        plant=plant,
        reference=reference,
        found=found,
        expected=expected,
        leaf_pairs=[(found_leaves[i], reference_leaves[j]) for i, j in pairs],
        extra=len(found_leaves) - len(pairs),
        missed=len(reference_leaves) - len(pairs),
    )


@dataclass(frozen=True)
class OrganEvaluation:
    """Agreement of every leaf trait (over paired leaves) and plant trait (over plants with a
    reference value), the leaf count exact on ``count_exact`` of ``plants`` plants, and the
    leaves found but not in the reference (``extra``) and the reverse (``missed``)."""

    pairs: list[PlantOrganPair]
    by_leaf_trait: dict[str, Agreement]
    by_plant_trait: dict[str, Agreement]
    count_exact: int
    extra: int
    missed: int

    def agreements(self) -> list[tuple[str, str, Agreement]]:
        """(trait, level ``leaf`` or ``plant``, agreement) of every trait, leaves first."""
        rows = [(t, "leaf", self.by_leaf_trait[t]) for t in LEAF_TRAITS]
        return rows + [(t, "plant", self.by_plant_trait[t]) for t in PLANT_TRAITS]

    def values(self, trait: str) -> tuple[list[float], list[float]]:
        """(algorithm, reference) values compared for ``trait`` (azimuths unwrapped to within
        180 degrees of the reference), as its agreement was computed."""
        if trait in LEAF_TRAITS:
            return _leaf_values(self.pairs, trait)
        return _plant_values(self.pairs, trait)


def _leaf_values(pairs: list[PlantOrganPair], trait: str) -> tuple[list[float], list[float]]:
    algorithm, reference = [], []
    for pair in pairs:
        for found, expected in pair.leaf_pairs:
            if found.get(trait) is None or expected.get(trait) is None:
                continue
            value, truth = float(found[trait]), float(expected[trait])
            if trait == "azimuth_deg":
                value = truth + azimuth_difference_deg(value, truth)
            algorithm.append(value)
            reference.append(truth)
    return algorithm, reference


def _plant_values(pairs: list[PlantOrganPair], trait: str) -> tuple[list[float], list[float]]:
    values = [
        (float(p.found[trait]), float(p.expected[trait]))
        for p in pairs
        if p.found.get(trait) is not None and p.expected.get(trait) is not None
    ]
    return [v[0] for v in values], [v[1] for v in values]


def evaluate_organs(pairs: list[PlantOrganPair]) -> OrganEvaluation:
    """Agreement of organ traits over ``pairs``. Azimuths are compared on the circle: the
    algorithm's value is unwrapped to within 180 degrees of the reference."""
    by_leaf = {t: agreement(*_leaf_values(pairs, t)) for t in LEAF_TRAITS}
    by_plant = {t: agreement(*_plant_values(pairs, t)) for t in PLANT_TRAITS}
    exact = sum(
        1
        for p in pairs
        if p.expected.get("leaf_count") is not None
        and int(p.found["leaf_count"]) == int(p.expected["leaf_count"])
    )
    return OrganEvaluation(
        pairs=pairs,
        by_leaf_trait=by_leaf,
        by_plant_trait=by_plant,
        count_exact=exact,
        extra=sum(p.extra for p in pairs),
        missed=sum(p.missed for p in pairs),
    )
