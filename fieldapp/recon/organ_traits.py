"""The organ step: one plant's organs and their traits (docs/TRAITS.md), from its points.

:func:`measure_organs` is called for each plant after the plants step; it needs nothing but
the plant's points (N, 3) in the field frame and its stem's foot.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import ConvexHull, QhullError

from fieldapp.recon.leaf_traits import LeafTraits, measure_leaves, stem_diameter_m
from fieldapp.recon.organs import ORGAN_STEM, ORGAN_WHORL, Organs, segment_organs
from fieldapp.recon.traits import PlantTraits

CANOPY_CELL_M = 0.01
"""Projected canopy area: occupied cells of this size on the ground plane."""


@dataclass(frozen=True)
class PlantOrgans:
    """A plant's organs (per-point labels) and their traits; lengths in metres.

    ``height_*_m`` above the local ground at the stem's foot: ``max`` the highest point,
    ``p99`` the 99th percentile of the points' heights, ``whorl`` the top of the stem and the
    whorl (``None`` without a stem).
    """

    organs: Organs
    leaves: list[LeafTraits]
    stem_diameter_m: float | None
    projected_area_m2: float
    hull_volume_m3: float
    height_max_m: float
    height_p99_m: float
    height_whorl_m: float | None

    @property
    def leaf_count(self) -> int:
        return len(self.leaves)

    @property
    def leaf_area_m2(self) -> float:
        return float(sum(leaf.area_m2 for leaf in self.leaves))


def foot_m(traits: PlantTraits) -> NDArray[np.float64]:
    """(3,) the stem's foot as the plants step found it: base xy, local ground z."""
    return np.array([traits.x_m, traits.y_m, traits.ground_z_m])


def measure_organs(points_m: NDArray[np.float64], foot_m: NDArray[np.float64]) -> PlantOrgans:
    """Organs and traits of one plant: points (N, 3) field frame, z up; ``foot_m`` (3,) the
    stem's foot (base xy, local ground z)."""
    if len(points_m) == 0:
        raise ValueError("a plant without points has no organs")
    organs = segment_organs(points_m, foot_m)
    axis = organs.axis
    leaves = (
        measure_leaves(points_m, organs.leaves, axis, organs.stem_radius_m) if organs.leaves else []
    )
    organs, leaves = numbered_from_the_bottom(organs, leaves)
    lowest = min((leaf.insertion_height_m for leaf in leaves), default=None)
    along, _ = axis.split(points_m)
    top = lowest if lowest is not None else float(along.max())
    diameter = stem_diameter_m(points_m, axis, organs.cut_radius_m, top)
    height = points_m[:, 2] - axis.foot_m[2]
    stem = np.isin(organs.organ, (ORGAN_STEM, ORGAN_WHORL))
    return PlantOrgans(
        organs=organs,
        leaves=leaves,
        stem_diameter_m=diameter,
        projected_area_m2=projected_area_m2(points_m),
        hull_volume_m3=hull_volume_m3(points_m),
        height_max_m=float(height.max()),
        height_p99_m=float(np.percentile(height, 99.0)),
        height_whorl_m=float(height[stem].max()) if stem.any() else None,
    )


def numbered_from_the_bottom(
    organs: Organs, leaves: list[LeafTraits]
) -> tuple[Organs, list[LeafTraits]]:
    """``organs`` and their ``leaves``' traits numbered again by the insertion heights the
    traits report (``leaves.csv``'s ``leaf_id``, "from the bottom", must agree with its own
    ``insertion_height_cm``): the segmentation orders leaves by where their innermost point
    meets the stem, the traits measure the insertion at the collar, and two leaves inserted
    a few millimetres apart can swap between the two. The points' ``leaf_id`` labels follow."""
    order = np.argsort([leaf.insertion_height_m for leaf in leaves], kind="stable")
    if np.array_equal(order, np.arange(len(leaves))):
        return organs, leaves
    indices = [organs.leaves[k] for k in order]
    leaf_id = np.zeros_like(organs.leaf_id)
    for number, points in enumerate(indices, start=1):
        leaf_id[points] = min(number, 255)
    traits = [replace(leaves[k], leaf_id=number) for number, k in enumerate(order, start=1)]
    return replace(organs, leaf_id=leaf_id, leaves=indices), traits


def projected_area_m2(points_m: NDArray[np.float64], cell_m: float = CANOPY_CELL_M) -> float:
    """Area of the plant's shadow from straight above: occupied ``cell_m`` cells (counted by
    one integer key per cell: ``np.unique`` of rows costs ten times as much)."""
    if len(points_m) == 0:
        return 0.0
    cells = np.floor(points_m[:, :2] / cell_m).astype(np.int64)
    cells -= cells.min(axis=0)
    keys = cells[:, 0] * (int(cells[:, 1].max()) + 1) + cells[:, 1]
    return float(len(np.unique(keys)) * cell_m * cell_m)


def hull_volume_m3(points_m: NDArray[np.float64]) -> float:
    """Volume of the points' convex hull; 0 when they are too few or flat."""
    if len(points_m) < 4:
        return 0.0
    try:
        return float(ConvexHull(points_m).volume)
    except QhullError:
        return 0.0
