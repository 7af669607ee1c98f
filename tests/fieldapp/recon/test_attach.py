"""Doubtful points (kept only by the statistical filter's raised floor) join the plant they
touch after the plants are found without them (:mod:`fieldapp.recon.attach`)."""

import numpy as np
import pytest

from fieldapp.recon.attach import ATTACH_GAP_M, ATTACH_REACH_M, _Nearest, attach_doubtful
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.filters import outlier_masks, split_outliers
from fieldapp.recon.plants import search_plants
from fieldapp.recon.settings import FilterSettings, PlantSettings

from .synthetic import LEAF_RGB, colored, ground_patch, seedling


def _strip(x0: float, x1: float, step: float, y: float = 0.0, z: float = 0.2) -> np.ndarray:
    x = np.arange(x0, x1 + 1e-9, step)
    return np.column_stack([x, np.full(len(x), y), np.full(len(x), z)])


def test_a_tip_joins_the_leaf_it_grows_from_and_a_stray_group_joins_nothing() -> None:
    leaf_a, leaf_b = _strip(0.0, 0.10, 0.002), _strip(0.30, 0.40, 0.002)
    points = np.concatenate([leaf_a, leaf_b])
    labels = np.repeat([0, 1], [len(leaf_a), len(leaf_b)])
    tip = _strip(0.106, 0.16, 0.006)  # on from a's end, sparser
    stray = _strip(0.20, 0.24, 0.006, y=0.2)  # touches neither
    found = attach_doubtful(points, labels, np.concatenate([tip, stray]))
    assert found[: len(tip)].tolist() == [0] * len(tip)
    assert found[len(tip) :].tolist() == [-1] * len(stray)


def test_a_chain_between_two_leaves_is_shared_by_path_length() -> None:
    """Each doubtful point of a chain that touches two plants takes the one it reaches by the
    shorter path through the chain, however near the other plant's points lie beside it."""
    leaf_a, leaf_b = _strip(0.0, 0.10, 0.002), _strip(0.20, 0.30, 0.002)
    points = np.concatenate([leaf_a, leaf_b])
    labels = np.repeat([3, 7], [len(leaf_a), len(leaf_b)])
    chain = _strip(0.106, 0.194, 0.008)  # 12 points, each step 8 mm
    found = attach_doubtful(points, labels, chain)
    nearer_a = np.abs(chain[:, 0] - 0.10) < np.abs(chain[:, 0] - 0.20)
    assert (found[nearer_a] == 3).all() and (found[~nearer_a] == 7).all()


def test_only_labelled_points_lead_and_steps_stop_at_the_reach() -> None:
    leaf = _strip(0.0, 0.10, 0.002)
    noise = _strip(0.10 + ATTACH_REACH_M / 2, 0.12, 0.002)  # in no plant (-1)
    points = np.concatenate([leaf, noise])
    labels = np.concatenate([np.zeros(len(leaf), np.intp), np.full(len(noise), -1)])
    beyond_noise = _strip(0.12 + 0.5 * ATTACH_REACH_M, 0.14, 0.004)
    gap = _strip(0.10 + 2.5 * ATTACH_REACH_M, 0.20, 0.004)  # a gap wider than a step
    found = attach_doubtful(points, labels, np.concatenate([beyond_noise, gap]), gap_m=0.0)
    assert (found == -1).all()
    assert attach_doubtful(points, labels, np.zeros((0, 3))).shape == (0,)
    assert (attach_doubtful(points, np.full(len(points), -1), leaf[:3]) == -1).all()


def test_a_group_that_reaches_no_plant_joins_the_nearest_within_the_gap() -> None:
    """A tip's sparse end, cut from its leaf by the stretch the filter removed outright,
    joins as a whole the plant nearest any of its points, within ``ATTACH_GAP_M``."""
    leaf_a, leaf_b = _strip(0.0, 0.10, 0.002), _strip(0.30, 0.40, 0.002)
    points = np.concatenate([leaf_a, leaf_b])
    labels = np.repeat([4, 9], [len(leaf_a), len(leaf_b)])
    near_a = _strip(0.10 + 0.6 * ATTACH_GAP_M, 0.10 + 0.6 * ATTACH_GAP_M + 0.05, 0.006)
    near_b = _strip(0.30 - 0.5 * ATTACH_GAP_M - 0.04, 0.30 - 0.5 * ATTACH_GAP_M, 0.006)
    alone = _strip(0.0, 0.06, 0.006, y=1.5 * ATTACH_GAP_M)  # beside a, beyond the gap
    groups = [near_a, near_b, alone]
    found = attach_doubtful(points, labels, np.concatenate(groups))
    sizes = np.cumsum([0] + [len(g) for g in groups])
    assert (found[sizes[0] : sizes[1]] == 4).all()
    assert (found[sizes[1] : sizes[2]] == 9).all()
    assert (found[sizes[2] : sizes[3]] == -1).all()


def _leaf_with_a_sparse_tip_and_strays(rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    """A dense leaf (20 cm across), a tip running 4 cm on from its edge one point every 6 mm
    (two rows 6 mm apart: each point has a neighbour within the radius filter's 8 mm; the
    mean distance to the 35 nearest grows from 1.1 to 3.6 cm along it, over the filter's limit
    of 2.4 cm at its end), and strays far from both."""
    leaf = ground_patch(rng, 0.1, 6000, noise_m=0.0005)
    leaf[:, 2] += 0.2
    tip = np.concatenate([_strip(0.106, 0.146, 0.006, y=y) for y in (0.0, 0.006)])
    strays = np.array([[0.5, 0.5, 0.6], [-0.5, 0.3, 0.3], [0.3, -0.4, 0.25]])
    return leaf, tip, strays


def test_the_raised_floor_finds_the_tip_doubtful_and_keeps_the_rest_as_before() -> None:
    leaf, tip, strays = _leaf_with_a_sparse_tip_and_strays(np.random.default_rng(3))
    points = np.concatenate([leaf, tip, strays])
    masks = outlier_masks(points, 35, 1.5, 0.008, 1, 1, 0.02, 0.04)
    radius = masks.radius  # the same as without doubtful points: test_filters.py
    np.testing.assert_array_equal(radius, outlier_masks(points, 35, 1.5, 0.008, 1, 1, 0.02).radius)
    is_tip = np.zeros(len(points), bool)
    is_tip[len(leaf) : len(leaf) + len(tip)] = True
    assert (~radius[is_tip]).sum() >= 4  # the filter takes the tip's end
    assert masks.doubtful[is_tip & ~radius].all()  # which is doubtful, not an outlier
    assert not masks.doubtful[-len(strays) :].any() and not radius[-len(strays) :].any()
    assert not (masks.doubtful & masks.radius).any()
    off = outlier_masks(points, 35, 1.5, 0.008, 1, 1, 0.02, 0.02)
    assert not off.doubtful.any()


def test_split_outliers_counts_the_doubtful_and_remove_outliers_is_unchanged() -> None:
    leaf, tip, strays = _leaf_with_a_sparse_tip_and_strays(np.random.default_rng(4))
    cloud = colored(np.concatenate([leaf, tip, strays]), LEAF_RGB)
    kept, doubtful, counts = split_outliers(cloud, FilterSettings())
    assert counts["doubtful_found"] == len(doubtful) > 0
    assert len(kept) + len(doubtful) <= len(cloud) - len(strays)
    same, same_counts = split_outliers(cloud, FilterSettings(), doubtful=False)[::2]
    np.testing.assert_array_equal(same.points, kept.points)
    assert "doubtful_found" not in same_counts


def test_a_plant_measured_with_its_doubtful_tip_and_a_stray_veil_left_out() -> None:
    rng = np.random.default_rng(8)
    plant = seedling(rng, 0.0, 0.0, 0.30, 0.30, 9000)  # disc at 18 cm, 15 cm radius
    other = seedling(rng, 0.8, 0.0, 0.30, 0.30, 9000)
    cloud = colored(np.concatenate([plant, other]), LEAF_RGB)
    tip = _strip(0.152, 0.19, 0.005, z=0.18)  # 4 cm on from the disc's rim, towards +x
    veil = _strip(0.40, 0.46, 0.005, z=0.5)  # far above, between the plants
    doubtful = colored(np.concatenate([tip, veil]), LEAF_RGB)
    settings, soil = PlantSettings(), np.zeros((0, 3))
    before = search_plants(cloud, soil, settings, 0.15)
    after = search_plants(cloud, soil, settings, 0.15, doubtful=doubtful)
    assert [p.traits.points for p in before.plants] == [9000, 9000]
    assert after.joined == len(tip)
    assert after.cloud is not None and len(after.cloud) == len(cloud) + len(tip)
    first, second = after.plants
    assert first.traits.points == 9000 + len(tip) and second.traits.points == 9000
    assert first.traits.width_m > before.plants[0].traits.width_m + 0.02
    assert second.traits.width_m == before.plants[1].traits.width_m
    np.testing.assert_array_equal(after.plants[1].cloud.points, before.plants[1].cloud.points)
    assert isinstance(after.cloud, Cloud)


def test_the_grid_lookup_never_misses_a_point_within_the_distance() -> None:
    """The tree the joins search holds only the labelled points the grid finds near a doubtful
    one: every point within the distance must be among them, at any offset and scale."""
    from scipy.spatial import cKDTree

    from fieldapp.recon.attach import _near

    rng = np.random.default_rng(11)
    for distance in (0.01, 0.05, 0.13):
        around = rng.uniform(-10 * distance, 30 * distance, (40, 3))
        direction = rng.normal(size=(400, 3))
        direction /= np.linalg.norm(direction, axis=1)[:, None]
        inside = np.repeat(around, 10, axis=0) + direction * distance * rng.uniform(0, 1, (400, 1))
        points = np.concatenate([rng.uniform(-15 * distance, 35 * distance, (20_000, 3)), inside])
        within = np.isfinite(cKDTree(around).query(points, distance_upper_bound=distance)[0])
        near = _near(points, around, distance)
        assert within.sum() > 40 and near[within].all()
        assert near.sum() < 0.5 * len(points)  # and not every point
    far = np.array([[0.0, 0.0, 0.0], [5000.0, 5000.0, 1.0]])  # a grid too large: every point
    assert _near(points, far, 0.01).all()


def test_a_group_about_as_near_two_plants_is_dropped() -> None:
    """Which of two plants a group lying about as near both belongs to is a guess: it joins
    only where every other plant lies ``ATTACH_MARGIN_M`` farther than the nearest."""
    leaf_a, leaf_b = _strip(0.0, 0.10, 0.002), _strip(0.19, 0.30, 0.002)
    points = np.concatenate([leaf_a, leaf_b])
    labels = np.repeat([1, 2], [len(leaf_a), len(leaf_b)])
    between = np.array([[0.14, 0.0, 0.2], [0.146, 0.0, 0.2]])  # 4.0 cm from a, 4.4 cm from b
    assert (attach_doubtful(points, labels, between) == -1).all()
    nearer_a = between - [0.02, 0.0, 0.0]  # 2.0 cm from a, 6.4 cm from b
    assert (attach_doubtful(points, labels, nearer_a) == 1).all()
    assert (attach_doubtful(points, labels, between, margin_m=0.0) == 1).all()


def _plant_with_a_cut_tip(gap_m: float) -> tuple[Cloud, Cloud, np.ndarray]:
    """Two seedlings 80 cm apart (discs of 15 cm radius at 18 cm) and a piece of the first's
    leaf tip, 60 points in two rows (too few to be a plant), ``gap_m`` on from its rim towards
    +x, in the cloud itself: what the outlier filters left of a drooping tip after removing the
    stretch between. Returns the cloud, an empty doubtful cloud and the piece."""
    rng = np.random.default_rng(21)
    plant = seedling(rng, 0.0, 0.0, 0.30, 0.30, 9000)
    other = seedling(rng, 0.8, 0.0, 0.30, 0.30, 9000)
    start = 0.15 + gap_m
    piece = np.concatenate([_strip(start, start + 0.087, 0.003, y=y, z=0.16) for y in (0, 0.004)])
    cloud = colored(np.concatenate([plant, other, piece]), LEAF_RGB)
    return cloud, colored(np.zeros((0, 3)), LEAF_RGB), piece


def test_a_piece_of_tip_too_small_to_be_a_plant_joins_the_plant_it_reaches() -> None:
    """A group no stem reaches and too small to be a plant (under ``min_points``) is a
    fragment: it joins the plant it reaches as a doubtful group does, instead of being
    dropped as noise (an independent renderer's touching plots: tips of 40-100 points 1-6 cm
    from their leaves, 4-5.5 cm of width each)."""
    settings, soil = PlantSettings(), np.zeros((0, 3))
    cloud, none, piece = _plant_with_a_cut_tip(0.6 * ATTACH_GAP_M)
    assert len(piece) < settings.min_points
    search = search_plants(cloud, soil, settings, 0.15, doubtful=none)
    first, second = search.plants
    assert first.traits.points == 9000 + len(piece) and second.traits.points == 9000
    reach = 0.15 + 0.6 * ATTACH_GAP_M + 0.087  # the piece's far end from the first's centre
    assert first.traits.width_m > 0.15 + reach - 0.01  # from the rim at -x to the piece's end
    assert any("fragments too small to be plants" in m for m in search.merges)
    # the control: beyond the gap the piece is noise, as before, and the width the disc's
    cloud, none, piece = _plant_with_a_cut_tip(1.5 * ATTACH_GAP_M)
    far = search_plants(cloud, soil, settings, 0.15, doubtful=none)
    assert [p.traits.points for p in far.plants] == [9000, 9000]
    assert far.plants[0].traits.width_m < 0.31
    # and without doubtful points at all, the same join
    alone = search_plants(*_plant_with_a_cut_tip(0.6 * ATTACH_GAP_M)[:1], soil, settings, 0.15)
    assert [p.traits.points for p in alone.plants] == [9000 + len(piece), 9000]


def test_a_tip_in_pieces_kept_and_doubtful_is_followed_through_both() -> None:
    """The fragments and the doubtful points are searched together: a doubtful stretch
    touching the plant leads on to a fragment beyond it."""
    settings, soil = PlantSettings(), np.zeros((0, 3))
    cloud, _, piece = _plant_with_a_cut_tip(3.0 * ATTACH_GAP_M)  # far beyond any gap
    bridge = _strip(0.155, 0.15 + 3.0 * ATTACH_GAP_M - 0.003, 0.006, z=0.16)
    search = search_plants(cloud, soil, settings, 0.15, doubtful=colored(bridge, LEAF_RGB))
    first = search.plants[0]
    assert search.joined == len(bridge)
    assert first.traits.points == 9000 + len(piece) + len(bridge)


def test_a_small_weed_on_the_soil_beside_a_plant_stays_out() -> None:
    """A piece too small to be a plant standing on the soil may be a weed: it joins a plant
    only point by point, never across a gap, where a piece of a tip floating above the soil
    crosses it (the control: the same piece lifted clear of the soil joins). The piece stands
    4.4-6.4 cm from the stem's side, two 2.5 cm cells from its cells, so that density
    clustering keeps it apart."""
    settings = PlantSettings()
    rng = np.random.default_rng(22)
    plant = seedling(rng, 0.0, 0.0, 0.30, 0.30, 9000)  # stem of 8 mm radius at the origin
    other = seedling(rng, 0.8, 0.0, 0.30, 0.30, 9000)
    soil = ground_patch(rng, 1.0, 4000)
    x = np.arange(0.052, 0.073, 0.004)
    # a tuft rising from the soil to 4.2 cm: its top stands clear, the tuft is one group
    rise = np.tile(np.arange(0.002, 0.043, 0.008), len(x))
    weed = np.column_stack([np.repeat(x, 6), np.zeros(len(rise)), rise])
    assert len(weed) < settings.min_points
    for lift, joins in ((0.0, False), (0.10, True)):
        piece = weed + np.array([0.0, 0.0, lift])
        cloud = colored(np.concatenate([plant, other, piece]), LEAF_RGB)
        search = search_plants(cloud, soil, settings, 0.15)
        first = search.plants[0]
        assert first.traits.points == 9000 + (len(piece) if joins else 0), lift


def test_the_nearest_other_plant_is_the_nearest_point_of_any_other_label_within_reach() -> None:
    """Each plant's tree asked once for all the points (a dense plot's lists of every plant
    point within 8 cm of each doubtful point took 2.5 GB) gives what a search of every point
    within reach gives: for a group labelled L, the nearest point of any plant but L."""
    rng = np.random.default_rng(7)
    points = rng.uniform(0.0, 0.4, (2000, 3))
    labels = rng.integers(0, 5, len(points))
    around = rng.uniform(0.0, 0.4, (300, 3))
    reach = 0.05
    nearest = _Nearest.of(points, labels, around, reach)
    gaps = np.linalg.norm(around[:, None, :] - points[None, :, :], axis=2)
    for label in range(5):
        for members in (np.arange(3), np.arange(100, 140), np.array([299])):
            others = gaps[np.ix_(members, np.flatnonzero(labels != label))]
            within = others[others <= reach]
            expected = within.min() if len(within) else np.inf
            assert nearest.besides(label, members) == pytest.approx(expected, abs=1e-12)
    far = _Nearest.of(points, labels, np.full((1, 3), 5.0), reach)
    assert far.besides(0, np.array([0])) == np.inf  # nothing within reach
