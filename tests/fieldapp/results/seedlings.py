"""A small labelled plot for the correction tests: two synthetic seedlings measured with the
reconstruction's own trait and organ code, written as a results folder."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fieldapp.recon.cloud import Cloud
from fieldapp.recon.organ_traits import PlantOrgans, foot_m, measure_organs
from fieldapp.recon.outputs import LeafRow, PlantRow, PointLabels, write_outputs
from fieldapp.recon.settings import ReconstructionSettings
from fieldapp.recon.traits import PlantTraits, measure_plant

from ..recon.synthetic import ground_patch, seedling

SETTINGS = ReconstructionSettings()
STEMS = ((0.0, 0.0), (0.3, 0.02))
"""Two seedlings 30 cm apart: 20 cm wide leaf discs, 10 cm of air between them."""


def seedlings(seed: int) -> list[NDArray[np.float64]]:
    rng = np.random.default_rng(seed)
    return [seedling(rng, x, y, 0.2, h, 3000) for (x, y), h in zip(STEMS, (0.22, 0.3), strict=True)]


SOIL = ground_patch(np.random.default_rng(9), 0.6, 4000, noise_m=0.0)


def traits_of(points: NDArray[np.float64]) -> PlantTraits:
    """What the reconstruction's trait code gives for these points (flat soil at z = 0)."""
    p = SETTINGS.plants
    return measure_plant(
        points,
        SOIL,
        p.base_slice_m,
        SETTINGS.ground.local_ground_radius_m,
        p.top_support_points,
        p.top_support_radius_m,
    )


def write_plot(folder: Path, groups: list[NDArray[np.float64]], ids: list[int]) -> Path:
    """A results folder as the reconstruction writes it: plants ``ids`` of points ``groups``,
    measured (traits and organs), labelled cloud, plant clouds, leaves, report."""
    points = np.concatenate(groups)
    cloud = Cloud(points, np.tile(np.array([50, 110, 25], np.uint8), (len(points), 1)))
    n = len(points)
    labels = PointLabels(np.zeros(n, np.int32), np.zeros(n, np.uint8), np.zeros(n, np.uint8))
    rows, leaves, clouds, plant_labels = [], [], {}, {}
    start = 0
    for plant, group in zip(ids, groups, strict=True):
        index = np.arange(start, start + len(group))
        start += len(group)
        traits = traits_of(group)
        organs = measure_organs(group, foot_m(traits))
        labels.plant_id[index] = plant
        labels.organ[index] = organs.organs.organ
        labels.leaf_id[index] = organs.organs.leaf_id
        rows.append(_row(plant, traits, organs))
        leaves += [
            LeafRow(plant, leaf.leaf_id, 100 * leaf.length_m, 0.0, 0.0, 0.0, 0.0, 0.0)
            for leaf in organs.leaves
        ]
        clouds[plant] = cloud.select(index)
        plant_labels[plant] = PointLabels(
            labels.plant_id[index], labels.organ[index], labels.leaf_id[index]
        )
    report = {"format": "fieldapp-reconstruction-report/1", "session": "s1", "warnings": []}
    report["run"] = str(folder) + str(ids)  # a new run writes a new report
    write_outputs(folder, rows, cloud, clouds, report, leaves, labels, plant_labels)
    return folder


def _row(plant: int, traits: PlantTraits, organs: PlantOrgans) -> PlantRow:
    return PlantRow(
        plant,
        traits.x_m,
        traits.y_m,
        100 * traits.height_m,
        100 * traits.width_m,
        traits.points,
        leaf_count=organs.leaf_count,
        height_max_cm=100 * organs.height_max_m,
    )


def apart_and_merged(base: Path) -> dict[str, Path]:
    """Two automatic results of seed 0's plot in ``base``: ``apart`` (plants 1 and 2) and
    ``merged`` (both seedlings as plant 1)."""
    groups = seedlings(0)
    return {
        "apart": write_plot(base / "apart", groups, [1, 2]),
        "merged": write_plot(base / "merged", [np.concatenate(groups)], [1]),
    }
