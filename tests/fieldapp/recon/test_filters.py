from pathlib import Path

import cv2
import numpy as np
import pytest

from fieldapp.recon import filters
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.exg import (
    BY_COLOUR,
    NO_SOIL_LEFT,
    choose_separation,
    excess_green,
    keep_soil,
    otsu_threshold,
)
from fieldapp.recon.filters import (
    filter_station,
    outlier_masks,
    pass_through,
    radius_outliers,
    remove_outliers,
    statistical_outliers,
    voxel_groups,
    voxel_keys,
    voxel_mean,
    voxel_mean_points,
)
from fieldapp.recon.geometry_split import LocalGround
from fieldapp.recon.settings import FilterSettings

from .synthetic import LEAF_RGB, SOIL_RGB, colored, cylinder, ground_patch


def test_excess_green_on_normalised_colour() -> None:
    colors = np.array(
        [[0, 255, 0], [255, 0, 0], [100, 100, 100], [0, 0, 0], [50, 110, 25]], np.uint8
    )
    np.testing.assert_allclose(
        excess_green(colors), [2.0, -1.0, 0.0, 0.0, (220 - 75) / 185], atol=1e-12
    )


def test_otsu_splits_two_modes_at_the_valley() -> None:
    rng = np.random.default_rng(0)
    low, high = rng.normal(0.0, 0.05, 50_000), rng.normal(0.8, 0.05, 5000)
    values = np.concatenate([low, high])
    threshold = otsu_threshold(values)
    assert np.mean(low > threshold) < 0.001 and np.mean(high <= threshold) < 0.001
    assert 0.15 < threshold < 0.65  # in the empty stretch between the modes
    with pytest.raises(ValueError, match="no values"):
        otsu_threshold(np.zeros(0))


def test_otsu_keeps_a_small_middle_class_with_the_greens() -> None:
    rng = np.random.default_rng(1)
    soil = rng.uniform(-0.02, 0.007, 1_700_000)
    stems = rng.uniform(0.14, 0.16, 1700)
    leaves = rng.uniform(0.38, 0.44, 34_000)
    threshold = otsu_threshold(np.concatenate([soil, stems, leaves]))
    assert 0.007 < threshold < 0.14
    # plain Otsu on the same values (OpenCV, 8-bit) would cut the stems off with the soil
    values = np.concatenate([soil, stems, leaves])
    span = values.max() - values.min()
    scaled = np.round((values - values.min()) / span * 255).astype(np.uint8)
    cv_threshold, _ = cv2.threshold(scaled, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    assert values.min() + cv_threshold / 255 * span > 0.14


def test_pass_through_keeps_the_band() -> None:
    kept = pass_through(np.array([-0.1, 0.005, 0.02, 1.0, 2.0]), 0.01, 1.5)
    assert kept.tolist() == [False, False, True, True, False]


def test_statistical_and_radius_outlier_removal_drop_isolated_points() -> None:
    rng = np.random.default_rng(1)
    surface = ground_patch(rng, 0.05, 4000, noise_m=0.0)  # about 1.6 mm spacing
    strays = np.array([[0.2, 0.2, 0.2], [-0.3, 0.1, 0.05], [0.0, 0.0, 0.1]])
    points = np.concatenate([surface, strays])
    sor = statistical_outliers(points, 35, 1.5)
    ror = radius_outliers(points, 0.008, 5)
    assert not sor[-3:].any() and not ror[-3:].any()
    assert sor[:-3].mean() > 0.95 and ror[:-3].all()


def _leaf_with_a_sparse_tip(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A leaf as the fused cloud has it (3 mm spacing, 20 cm across) ending in a tip that
    narrows from 2.4 cm to nothing over 4 cm, on a 3 mm grid, and no outlier; the tip's mask.
    The tip's end points' mean distances to their 35 nearest reach 19 mm (the 99.9th
    percentile measured on plants' surfaces: 15-19 mm)."""
    leaf = ground_patch(rng, 0.1, 4000, noise_m=0.0005)
    leaf[:, 2] += 0.2
    tip = [
        [0.1 + x, y, 0.2]
        for x in np.arange(0.0, 0.04, 0.003)
        for y in np.arange(-0.012 * (1 - x / 0.04), 0.012 * (1 - x / 0.04) + 1e-9, 0.003)
    ]
    return np.concatenate([leaf, tip]), np.arange(len(leaf) + len(tip)) >= len(leaf)


def test_the_statistical_filter_keeps_a_clean_cloud_s_sparse_tip() -> None:
    """Without outliers to widen it, the paper's limit (average + 1.5 standard deviations)
    falls within a real surface's own spread and takes the sparsest real points, a blade's
    tip; the floor (``sor_min_distance_m``) keeps them, and still drops strays."""
    points, tip = _leaf_with_a_sparse_tip(np.random.default_rng(5))
    paper = statistical_outliers(points, 35, 1.5)
    assert (~paper[tip]).sum() >= 10 and (~paper[~tip]).sum() >= 100  # the tip, the rims
    floored = statistical_outliers(
        points, 35, 1.5, min_distance_m=FilterSettings().sor_min_distance_m
    )
    assert floored.all()
    strays = np.array([[0.4, 0.4, 0.5], [-0.4, 0.3, 0.1]])
    with_strays = np.concatenate([points, strays])
    kept = statistical_outliers(with_strays, 35, 1.5, min_distance_m=0.02)
    assert kept[: len(points)].all() and not kept[-2:].any()
    masks = outlier_masks(with_strays, 35, 1.5, 0.008, 1, min_distance_m=0.02)
    np.testing.assert_array_equal(masks.statistical, kept)


def test_the_floor_leaves_a_noisy_cloud_s_limit_alone() -> None:
    """Where outliers widen the spread (every simulated plot measured: limits of 26-38 mm)
    the paper's limit is above the floor and decides alone."""
    rng = np.random.default_rng(6)
    points, _ = _leaf_with_a_sparse_tip(rng)
    noisy = np.concatenate([points, rng.uniform(-0.5, 0.5, (300, 3))])
    np.testing.assert_array_equal(
        statistical_outliers(noisy, 35, 1.5, min_distance_m=0.02),
        statistical_outliers(noisy, 35, 1.5),
    )


def _sor_then_ror(
    points: np.ndarray,
    neighbors: int,
    std_ratio: float,
    radius_m: float,
    min_points: int,
    min_distance_m: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The two filters one after the other, each with its own tree (the paper's order)."""
    statistical = statistical_outliers(points, neighbors, std_ratio, min_distance_m=min_distance_m)
    radius = np.zeros(len(points), dtype=bool)
    radius[statistical] = radius_outliers(points[statistical], radius_m, min_points)
    return statistical, radius


@pytest.mark.parametrize(("block", "spare"), [(65_536, 3), (1000, 3), (7, 3), (1000, 0)])
@pytest.mark.parametrize(
    ("neighbors", "radius_m", "min_points"),
    [(35, 0.008, 1), (35, 0.008, 5), (8, 0.02, 12), (3, 0.05, 40), (35, 0.001, 1)],
)
def test_one_query_gives_the_masks_of_sor_then_ror(
    neighbors: int, radius_m: float, min_points: int, block: int, spare: int, monkeypatch
) -> None:
    """Whatever the radius and the count asked (beyond the neighbours searched, too: the
    points left unsure are counted again), duplicates and strays included, however the
    query is cut into blocks and however few of the neighbours within the radius are kept
    (none spare: every point short of its count among them is counted again)."""
    monkeypatch.setattr(filters, "OUTLIER_QUERY_BLOCK", block)
    monkeypatch.setattr(filters, "ROR_SPARE", spare)
    rng = np.random.default_rng(neighbors + min_points)
    surface = ground_patch(rng, 0.05, 3000, noise_m=0.0005)
    blobs = rng.normal(0.0, 0.004, (6, 30, 3)) + rng.uniform(-0.2, 0.2, (6, 1, 3))
    strays = rng.uniform(-0.3, 0.3, (40, 3))
    points = np.concatenate([surface, surface[:50], blobs.reshape(-1, 3), strays])
    masks = outlier_masks(points, neighbors, 1.5, radius_m, min_points)
    expected_statistical, expected_radius = _sor_then_ror(
        points, neighbors, 1.5, radius_m, min_points
    )
    np.testing.assert_array_equal(masks.statistical, expected_statistical)
    np.testing.assert_array_equal(masks.radius, expected_radius)
    assert 0 < masks.radius.sum() < len(points)  # not all kept, not all dropped
    # the doubtful points: kept by the two filters in turn with the floor raised, and not
    # without; with the limit at the mean distance (std_ratio 0) some lie between
    tight = outlier_masks(points, neighbors, 0.0, radius_m, min_points, 1, 0.0, DOUBTFUL_M)
    _, strict = _sor_then_ror(points, neighbors, 0.0, radius_m, min_points)
    _, loose = _sor_then_ror(points, neighbors, 0.0, radius_m, min_points, DOUBTFUL_M)
    np.testing.assert_array_equal(tight.radius, strict)
    np.testing.assert_array_equal(tight.doubtful, loose & ~strict)
    assert tight.doubtful.any()


DOUBTFUL_M = 0.06
"""A raised floor for the doubtful points, over the mean distances of the clouds here."""


@pytest.mark.parametrize("spare", [0, 3])
@pytest.mark.parametrize("min_points", [1, 5, 20])
def test_one_query_where_inliers_and_outliers_interleave(
    spare: int, min_points: int, monkeypatch
) -> None:
    """With no spread allowed (std_ratio 0) about half the points are statistical outliers,
    interleaved with the inliers: the nearest neighbours kept of a point are often outliers
    while inliers lie farther within the radius, and it must be counted again."""
    monkeypatch.setattr(filters, "ROR_SPARE", spare)
    rng = np.random.default_rng(min_points)
    points = ground_patch(rng, 0.05, 4000, noise_m=0.001)
    masks = outlier_masks(points, 35, 0.0, 0.004, min_points)
    expected_statistical, expected_radius = _sor_then_ror(points, 35, 0.0, 0.004, min_points)
    assert 0.3 < masks.statistical.mean() < 0.7
    np.testing.assert_array_equal(masks.statistical, expected_statistical)
    np.testing.assert_array_equal(masks.radius, expected_radius)


@pytest.mark.parametrize("n", [0, 1, 2, 5])
def test_one_query_on_clouds_smaller_than_the_neighbours(n: int) -> None:
    points = np.random.default_rng(n).uniform(0.0, 0.01, (n, 3))
    masks = outlier_masks(points, 35, 1.5, 0.008, 1, 1, 0.0, DOUBTFUL_M)
    expected_statistical, expected_radius = _sor_then_ror(points, 35, 1.5, 0.008, 1)
    np.testing.assert_array_equal(masks.statistical, expected_statistical)
    np.testing.assert_array_equal(masks.radius, expected_radius)
    assert not masks.doubtful.any()


def test_voxel_mean_averages_points_and_colours_per_voxel() -> None:
    points = np.array([[0.001, 0.001, 0.001], [0.003, 0.003, 0.003], [0.011, 0.0, 0.0]])
    colors = np.array([[0, 100, 0], [100, 200, 0], [7, 7, 7]], np.uint8)
    out = voxel_mean(Cloud(points, colors), 0.01)
    order = np.argsort(out.points[:, 0])
    np.testing.assert_allclose(out.points[order], [[0.002, 0.002, 0.002], [0.011, 0.0, 0.0]])
    assert out.colors[order].tolist() == [[50, 150, 0], [7, 7, 7]]


@pytest.mark.parametrize("order", ["scan", "shuffled", "reversed"])
def test_voxel_groups_number_the_voxels_as_np_unique_does(order: str) -> None:
    # a stable sort in place of np.unique's: the same numbering, so the same voxel means in
    # the same order, whatever order the points come in (a camera's scan order, a plot's
    # stations one after another, or none)
    rng = np.random.default_rng(7)
    points = np.cumsum(rng.normal(0.0, 0.004, (5000, 3)), axis=0)  # runs, as a scan has
    points = np.concatenate([points, points[:700] + 0.0005])  # voxels shared, far apart
    if order == "shuffled":
        points = points[rng.permutation(len(points))]
    elif order == "reversed":
        points = points[::-1]
    group, counts = voxel_groups(points, 0.01)
    _, inverse, expected = np.unique(
        voxel_keys(points, 0.01), return_inverse=True, return_counts=True
    )
    assert group.tolist() == inverse.ravel().tolist()
    assert counts.tolist() == expected.tolist()
    assert counts.sum() == len(points) and (counts > 1).any()


def test_voxel_mean_points_are_voxel_mean_s_points() -> None:
    rng = np.random.default_rng(3)
    points = rng.uniform(-1.0, 1.0, (20_000, 3))
    colors = rng.integers(0, 255, (20_000, 3), dtype=np.uint8)
    full = voxel_mean(Cloud(points, colors), 0.05)
    assert np.array_equal(voxel_mean_points(points, 0.05), full.points)
    assert voxel_mean_points(np.empty((0, 3)), 0.05).shape == (0, 3)


def test_filter_chain_keeps_the_plant_and_drops_soil_and_strays() -> None:
    rng = np.random.default_rng(2)
    soil = ground_patch(rng, 1.0, 60_000, noise_m=0.002)
    soil[:100, 2] = 0.5  # non-green things well above the ground: not soil
    plant = colored(cylinder(rng, 0.2, 0.1, 0.01, 0.3, 20_000), LEAF_RGB)
    low_green = colored(np.array([[0.5, 0.5, 0.005]]), LEAF_RGB)  # a weed's speck on the soil
    green_stray = colored(np.array([[0.6, 0.6, 0.4]]), LEAF_RGB)
    green = Cloud.concatenate([plant, low_green, green_stray])
    result = filter_station(
        green, colored(soil, SOIL_RGB), FilterSettings(), soil_band_m=0.03, soil_voxel_m=0.02
    )
    assert list(result.kept) == ["excess_green", "pass_through", "voxel_mean"]
    z = green.points[:, 2]
    clear = z - LocalGround(soil[np.abs(soil[:, 2]) <= 0.03]).under(green.points[:, :2])
    assert result.kept["excess_green"] == 20_002
    assert result.kept["pass_through"] == int(np.sum((clear >= 0.01) & (z <= 1.5))) < 20_001
    assert result.kept["voxel_mean"] < 20_001
    assert len(result.soil_m) > 1000 and np.abs(result.soil_m[:, 2]).max() < 0.03
    assert np.any(result.plants.points[:, 2] > 0.35)  # the stray is still there

    kept, counts_after = remove_outliers(result.plants, FilterSettings())
    points = kept.points
    assert np.all(np.hypot(points[:, 0] - 0.2, points[:, 1] - 0.1) < 0.0125)
    ground = LocalGround(soil[np.abs(soil[:, 2]) <= 0.03]).under(points[:, :2])
    assert (points[:, 2] - ground).min() >= 0.0099 and points[:, 2].max() <= 0.3 + 1e-9
    assert list(counts_after) == ["statistical_outliers", "radius_outliers"]
    assert counts_after["radius_outliers"] == len(kept) > 0.95 * len(result.plants)


def test_points_not_green_by_their_own_colour_must_stand_clearer_of_the_ground() -> None:
    """What the rim rules keep beside green is not green itself: a leaf's rim, or the soil
    beside a straw or a low leaf. Soil on a clod 2 cm up passed the 1 cm pass-through and
    joined the plants (an independent renderer's seedling 32 % soil, 19 cm too wide); it
    must now stand 2.5 cm clear. So must a point without colour (black: libfreenect2's holes;
    dark: a JPEG's black, a shadow), which the colour step grows along a leaf by its own rule:
    near the ground it is mostly the soil beside a stem that the colour camera does not see.
    A green point 2 cm up is kept, and every kind of point 4 cm up."""
    rng = np.random.default_rng(5)
    soil = ground_patch(rng, 1.0, 60_000, noise_m=0.002)
    low = [[0.3, 0.3], [0.3, 0.5], [0.5, 0.3], [0.5, 0.5], [0.4, 0.4]]
    colours = np.array([SOIL_RGB, LEAF_RGB, (0, 0, 0), (14, 12, 10), (10, 24, 8)], np.uint8)
    at = np.array([[x, y, z] for z in (0.02, 0.04) for x, y in low])
    result = filter_station(
        Cloud(at, np.concatenate([colours, colours])),
        colored(soil, SOIL_RGB),
        FilterSettings(voxel_size_m=0.001),
        soil_band_m=0.03,
        soil_voxel_m=0.02,
    )
    kept = {tuple(np.round(p, 3)) for p in result.plants.points}
    assert kept == {(0.3, 0.5, 0.02)} | {(x, y, 0.04) for x, y in low}
    before = FilterSettings(voxel_size_m=0.001, pass_through_dull_min_m=0.0)
    again = filter_station(
        Cloud(at, np.concatenate([colours, colours])), colored(soil, SOIL_RGB), before, 0.03, 0.02
    )
    assert len(again.plants) == 10


def test_a_threshold_that_leaves_no_soil_separates_by_geometry() -> None:
    """ExG -1 keeps every colour (white reference spheres among plants): the station would
    have no soil sample, so no ground to level on; geometry keeps one."""
    rng = np.random.default_rng(0)
    exg = np.concatenate([rng.normal(0.0, 0.03, 9900), rng.normal(0.45, 0.05, 100)])
    assert choose_separation(exg) == BY_COLOUR
    assert keep_soil(BY_COLOUR, exg, otsu_threshold(exg)) == BY_COLOUR  # 99 % soil
    everything = keep_soil(BY_COLOUR, exg, -1.0)
    assert everything.by_geometry and everything.reason == NO_SOIL_LEFT
    assert keep_soil(BY_COLOUR, exg, float(np.quantile(exg, 0.02))) == BY_COLOUR


def test_the_neighbour_search_runs_on_the_threads_asked_with_the_same_masks() -> None:
    """pykdtree's own OpenMP takes the thread count (its libgomp, not the system's); one
    thread or two, the masks are the same."""
    import ctypes

    import pykdtree

    libraries = list((Path(pykdtree.__file__).parent.parent / "pykdtree.libs").glob("libgomp*"))
    assert libraries, "the locked pykdtree wheel brings its own libgomp (requirements.lock)"
    rng = np.random.default_rng(4)
    points = np.concatenate([ground_patch(rng, 0.05, 4000), rng.uniform(-0.3, 0.3, (30, 3))])
    masks = []
    for threads in (1, 2):
        found = outlier_masks(points, 35, 1.5, 0.008, 1, threads)
        masks.append((found.statistical, found.radius))
        for library in libraries:
            assert ctypes.CDLL(str(library)).omp_get_max_threads() == threads
    np.testing.assert_array_equal(masks[0][0], masks[1][0])
    np.testing.assert_array_equal(masks[0][1], masks[1][1])
    assert 0 < masks[0][1].sum() < len(points)


def test_the_openmp_lookup_says_what_it_found(
    caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Under ``fieldapp -v`` each libgomp of pykdtree's is named with its thread count read
    back, and a pykdtree without one names the folder looked in: the built bundle's check
    (packaging/check_bundle.sh) reads these lines to catch a silent fallback."""
    import pykdtree

    def messages(threads: int) -> list[str]:
        caplog.clear()
        filters._pykdtree_openmp.cache_clear()  # looked up again, so the lookup logs too
        try:
            filters._openmp_threads(threads)
        finally:
            filters._pykdtree_openmp.cache_clear()
        return [record.getMessage() for record in caplog.records]

    caplog.set_level("DEBUG", logger="fieldapp.recon.filters")
    folder = Path(pykdtree.__file__).parent.parent / "pykdtree.libs"
    own = sorted(folder.glob("libgomp*"))
    none = "pykdtree's OpenMP: no libgomp in {}, OMP_NUM_THREADS sets its threads"
    for threads in (1, 2):
        expected = [f"pykdtree's OpenMP: {library.name} on {threads} threads" for library in own]
        assert messages(threads) == (expected or [none.format(folder)])
    monkeypatch.setattr(pykdtree, "__file__", "/nowhere/pykdtree/__init__.py")
    assert messages(2) == [none.format(Path("/nowhere/pykdtree.libs"))]


def test_voxel_keys_are_one_per_voxel_and_refuse_a_span_they_cannot_pack() -> None:
    from fieldapp.recon.filters import voxel_keys

    rng = np.random.default_rng(5)
    points = rng.uniform(-3.0, 3.0, (5000, 3))
    keys = voxel_keys(points, 0.01)
    cells = np.floor(points / 0.01).astype(np.int64)
    _, by_cell = np.unique(cells, axis=0, return_inverse=True)
    _, by_key = np.unique(keys, return_inverse=True)
    assert np.array_equal(by_cell.ravel(), by_key.ravel())  # the same partition
    with pytest.raises(ValueError, match="more than 2"):
        voxel_keys(np.array([[0.0, 0.0, 0.0], [0.0, 30_000.0, 0.0]]), 0.01)
