"""Two plants standing on one base are one plant (``plants._merge_shared_bases``).

Seen on a seedling plot (seed 901) whose depth had 3 mm x d^2 more noise and half again as
many mixed pixels (12 mm at 2 m, the Kinect v2 outdoors at grazing angles): two drooping
leaves' veils were read as stem columns 14 and 16 cm from their plants' stems, their paths
took the plants' lower parts, and four "plants" stood in pairs 1.4 and 1.6 cm apart (p06 20.8
cm tall for 31.2, 28.6 cm wide for 48.0). Merged, 31.6 / 47.3 and 26.3 / 35.9 (for 26.6 /
36.5).
"""

from __future__ import annotations

import numpy as np

from fieldapp.recon.cloud import Cloud
from fieldapp.recon.plants import Plant, _merge_shared_bases
from fieldapp.recon.traits import Circle, PlantTraits


def _plant(plant_id: int, xy: tuple[float, float], height_m: float) -> Plant:
    traits = PlantTraits(xy[0], xy[1], height_m, 300, 0.0, Circle(xy[0], xy[1], 0.1))
    return Plant(plant_id, traits, Cloud(np.zeros((0, 3)), np.zeros((0, 3), np.uint8)))


def test_a_plant_on_a_taller_ones_base_becomes_part_of_it() -> None:
    plants = [
        _plant(1, (0.0, 0.0), 0.21),  # the plant's top half, on its own stem
        _plant(2, (0.014, 0.0), 0.31),  # its lower part, taken from a phantom stem's path
        _plant(3, (0.8, 0.0), 0.25),  # the neighbour, 80 cm off
        _plant(4, (0.8, 0.13), 0.05),  # a small plant 13 cm from it: not on its base
    ]
    labels = np.array([0, 0, 1, 1, 1, 2, 3, 3, -1])
    plant_labels = {1: 0, 2: 1, 3: 2, 4: 3}
    merges: list[str] = []
    assert _merge_shared_bases(labels, plants, plant_labels, 0.12, merges)
    assert labels.tolist() == [1, 1, 1, 1, 1, 2, 3, 3, -1]  # into the taller one's label
    assert merges == ["1 plants standing on another plant's base merged into it"]


def test_plants_apart_are_left_alone() -> None:
    plants = [_plant(i + 1, (0.8 * i, 0.0), 0.3) for i in range(4)]
    labels = np.arange(4)
    merges: list[str] = []
    assert not _merge_shared_bases(labels, plants, {i + 1: i for i in range(4)}, 0.12, merges)
    assert labels.tolist() == [0, 1, 2, 3] and merges == []
