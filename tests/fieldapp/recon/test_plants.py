import numpy as np

from fieldapp.recon.cloud import Cloud
from fieldapp.recon.plants import (
    NOISE,
    apply_grid_prior,
    drop_small,
    find_plants,
    order_by_position,
    voxel_components,
)
from fieldapp.recon.settings import GridPrior, PlantSettings

from .synthetic import LEAF_RGB, colored, cylinder, seedling


def test_voxel_components_separate_apart_and_join_touching() -> None:
    a = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.02, 0.01, 0.0]])
    b = a + np.array([0.2, 0.0, 0.0])
    diagonal = np.array([[0.215, 0.015, 0.015]])  # touches b's last voxel at a corner
    labels = voxel_components(np.concatenate([a, b, diagonal]), 0.01)
    assert len(set(labels[:3])) == 1 and len(set(labels[3:])) == 1
    assert labels[0] != labels[3]


def test_drop_small_marks_noise() -> None:
    labels = drop_small(np.array([0, 0, 0, 1, 2, 2]), 2)
    assert labels.tolist() == [0, 0, 0, NOISE, 2, 2]


def test_order_by_position_reads_rows_then_columns() -> None:
    positions = np.array([[0.8, 0.01], [0.0, 0.8], [0.0, -0.01], [0.8, 0.79]])
    assert order_by_position(positions, 0.1) == [2, 0, 1, 3]


def test_find_plants_measures_each_cylinder_and_drops_specks() -> None:
    rng = np.random.default_rng(0)
    truth = [(0.0, 0.0, 0.30, 0.30), (0.8, 0.0, 0.45, 0.25), (0.0, 0.8, 0.40, 0.40)]
    parts = [colored(seedling(rng, x, y, w, h, 6000), LEAF_RGB) for x, y, w, h in truth]
    speck = colored(rng.normal([0.4, 0.4, 0.1], 0.002, (20, 3)), LEAF_RGB)
    plants = find_plants(
        Cloud.concatenate([*parts, speck]), np.zeros((0, 3)), PlantSettings(), 0.15
    )
    assert [p.id for p in plants] == [1, 2, 3]
    for plant, (x, y, w, h) in zip(plants, truth, strict=True):
        assert abs(plant.traits.x_m - x) < 0.002 and abs(plant.traits.y_m - y) < 0.002
        assert abs(plant.traits.height_m - h) < 1e-6
        assert abs(plant.traits.width_m - w) < 1e-6
        assert plant.traits.points == len(plant.cloud) == 6000


def test_grid_prior_splits_touching_canopies_and_merges_fragments() -> None:
    rng = np.random.default_rng(1)
    left = cylinder(rng, 0.0, 0.0, 0.01, 0.3, 3000)
    right = cylinder(rng, 0.3, 0.0, 0.01, 0.3, 3000)
    bridge = np.column_stack([np.linspace(0, 0.3, 400), np.zeros(400), np.full(400, 0.2)])  # leaves
    fragment_stem = cylinder(rng, 0.0, 0.6, 0.01, 0.1, 1000)
    fragment_leaf = cylinder(rng, 0.05, 0.6, 0.01, 0.05, 500) + np.array(
        [0, 0, 0.2]
    )  # floating leaf
    points = np.concatenate([left, right, bridge, fragment_stem, fragment_leaf])
    labels = voxel_components(points, 0.015)
    assert len(np.unique(labels[:6400])) == 1  # touching: one cluster
    grid = GridPrior(rows=2, columns=2, row_spacing_m=0.6, column_spacing_m=0.3, snap_radius_m=0.1)
    split = apply_grid_prior(points, labels, grid, base_height_m=0.04)
    assert split[0] != split[3000]
    assert len(np.unique(split[:3000])) == 1 and len(np.unique(split[3000:6000])) == 1
    # the floating leaf claims no node (it is not low) and stays its own cluster here
    assert len(np.unique(split[6400:7400])) == 1


def test_grid_prior_merges_two_low_fragments_at_one_node() -> None:
    rng = np.random.default_rng(2)
    a = cylinder(rng, 0.0, 0.0, 0.005, 0.2, 1000)
    b = cylinder(rng, 0.06, 0.0, 0.005, 0.2, 1000)  # a tiller 6 cm away, disconnected
    points = np.concatenate([a, b])
    labels = voxel_components(points, 0.015)
    assert labels[0] != labels[1500]
    grid = GridPrior(rows=1, columns=1, row_spacing_m=1.0, column_spacing_m=1.0, snap_radius_m=0.1)
    merged = apply_grid_prior(points, labels, grid, base_height_m=0.04)
    assert len(np.unique(merged)) == 1
