"""Excess green in integers (issue 22) gives the values of the float64 formula, bit for bit:
the reconstruction's outputs did not change with it."""

from __future__ import annotations

import numpy as np
import pytest

from fieldapp.recon.exg import (
    BY_COLOUR,
    EXG_KEYS,
    NO_KEY,
    NOISE_SIGMAS,
    above_the_soil,
    excess_green,
    exg_keys,
    exg_of_keys,
    exg_tally,
    exg_values,
    green_contrast,
    grey_group,
    keep_soil,
    noise_floors,
    otsu_threshold,
    thresholds_by_key,
)


def _float64_formula(colors: np.ndarray) -> np.ndarray:
    rgb = colors.astype(np.float64)
    total = rgb.sum(axis=1)
    total[total == 0] = 1.0
    return (2.0 * rgb[:, 1] - rgb[:, 0] - rgb[:, 2]) / total


def test_integer_excess_green_equals_the_float64_formula_bit_for_bit() -> None:
    rng = np.random.default_rng(22)
    levels = np.array([0, 1, 2, 127, 128, 254, 255], np.uint8)
    corners = np.stack(np.meshgrid(levels, levels, levels), axis=-1).reshape(-1, 3)
    colors = np.concatenate([corners, rng.integers(0, 256, (200_000, 3), dtype=np.uint8)])
    exg = excess_green(colors)
    assert exg.dtype == np.float64
    np.testing.assert_array_equal(exg.view(np.int64), _float64_formula(colors).view(np.int64))
    assert exg[0] == 0.0 and exg.min() >= -1.0 and exg.max() <= 2.0


def test_a_colour_key_fixes_the_excess_green_bit_for_bit() -> None:
    """The stations' pixels are tallied by colour key (issue 22): the key's value must be the
    pixel's ExG exactly, or the threshold and the green pixels would change."""
    rng = np.random.default_rng(23)
    levels = np.array([0, 1, 2, 127, 128, 254, 255], np.uint8)
    corners = np.stack(np.meshgrid(levels, levels, levels), axis=-1).reshape(-1, 3)
    colors = np.concatenate([corners, rng.integers(0, 256, (200_000, 3), dtype=np.uint8)])
    keys = exg_keys(colors)
    assert keys.dtype == np.int32 and keys.min() >= 0 and keys.max() < EXG_KEYS
    by_key = exg_of_keys()[keys]
    np.testing.assert_array_equal(by_key.view(np.int64), excess_green(colors).view(np.int64))
    green, total = np.divmod(keys, 766)  # the key is G * 766 + R + G + B
    np.testing.assert_array_equal(green, colors[:, 1])
    np.testing.assert_array_equal(total, colors.astype(np.int64).sum(axis=1))


def test_the_tallied_values_give_the_pixels_otsu_threshold_bit_for_bit() -> None:
    rng = np.random.default_rng(24)
    soil = rng.normal((120, 95, 70), 12, (60_000, 3))
    leaves = rng.normal((60, 140, 40), 15, (3_000, 3))
    colors = np.clip(np.concatenate([soil, leaves]), 0, 255).astype(np.uint8)
    values, weights = exg_values(exg_tally(exg_keys(colors)))
    assert weights.sum() == len(colors) and len(values) < len(colors) / 2
    exg = excess_green(colors)
    threshold = otsu_threshold(values, weights)
    assert threshold == otsu_threshold(exg)
    assert green_contrast(values, weights) == pytest.approx(green_contrast(exg), abs=1e-12)
    assert green_contrast(values, weights) > 0.2
    for cut in (threshold, -1.0, float(np.quantile(exg, 0.005))):
        assert keep_soil(BY_COLOUR, values, cut, weights) == keep_soil(BY_COLOUR, exg, cut)
    assert keep_soil(BY_COLOUR, values, -1.0, weights).by_geometry


def _pixels(rgb: tuple[int, int, int], noise: float, count: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.clip(np.rint(rng.normal(rgb, noise, (count, 3))), 0, 255).astype(np.uint8)


def test_dark_soil_s_noise_raises_the_bar_for_dark_pixels_alone() -> None:
    """Per-channel noise of 4 levels: the dark soil's pixels spread far past a threshold the
    bright soil's never reach; the floors hold dark soil back and keep the leaves, bright
    and in shade."""
    bright_soil = _pixels((150, 118, 92), 4, 200_000, 1)
    dark_soil = _pixels((42, 37, 31), 4, 60_000, 2)
    bright_leaf, shaded_leaf = (
        _pixels((70, 150, 45), 4, 8_000, 3),
        _pixels((22, 50, 14), 4, 2_000, 4),
    )
    colors = np.concatenate([bright_soil, dark_soil, bright_leaf, shaded_leaf])
    tally = exg_tally(exg_keys(colors))
    threshold = 0.2  # as the stations' thresholds measured (0.15-0.25)
    passed = excess_green(dark_soil) > threshold
    assert passed.sum() >= 50  # the station's threshold alone lets dark soil through
    floors = noise_floors(tally, threshold, NOISE_SIGMAS)
    assert floors[42 + 37 + 31] > threshold > floors[150 + 118 + 92]
    green = thresholds_by_key(threshold, floors)
    assert green[exg_keys(dark_soil)].sum() <= 2
    assert not green[exg_keys(bright_soil)].any()
    assert green[exg_keys(bright_leaf)].all()
    assert green[exg_keys(shaded_leaf)].mean() >= 0.99
    assert not green[NO_KEY]


def test_without_soil_to_measure_there_is_no_floor() -> None:
    leaves = _pixels((70, 150, 45), 4, 8_000, 5)
    tally = exg_tally(exg_keys(leaves))
    assert np.isneginf(noise_floors(tally, -1.0, NOISE_SIGMAS)).all()  # every pixel green


CORNER_STATION_EXG = (
    7, 7, 5, 10, 15, 40, 42, 102, 207, 482, 1123, 2903, 6599, 14819, 31771, 56661, 98173,
    148009, 191321, 241218, 201394, 189060, 140649, 93820, 53309, 27683, 12962, 5731, 2296,
    986, 380, 187, 82, 45, 42, 33, 31, 43, 38, 57, 83, 120, 145, 198, 383, 340, 489, 569, 628,
    669, 584, 611, 544, 464, 400, 348, 236, 198, 168, 143,
)  # fmt: skip
"""The pixels of an independent renderer's corner station with twice its colour noise, by
ExG in 60 bins over -0.4..0.8: the soil's hump (spread 0.05) and the leaves, 0.7 %."""


def test_otsu_s_cut_inside_noisy_soil_is_moved_above_it() -> None:
    """Otsu's criterion favours the larger class: with the leaves a sliver of the pixels it
    cuts the soil's own hump (that station: 0.015-0.05 against 0.20 elsewhere, 39 % of its
    pixels "green"). Above the soil's spread the leaves stand apart."""
    edges = np.linspace(-0.4, 0.8, len(CORNER_STATION_EXG) + 1)
    values = (edges[:-1] + edges[1:]) / 2
    weights = np.array(CORNER_STATION_EXG, dtype=np.int64)
    otsu = otsu_threshold(values, weights)
    assert otsu < 0.1 and weights[values > otsu].sum() > 0.1 * weights.sum()  # in the soil
    moved = above_the_soil(values, weights, otsu)
    assert 0.1 < moved < 0.45  # 0.20 on the station's own pixels (these are binned by 0.02)
    assert weights[values > moved].sum() < 0.015 * weights.sum()


@pytest.mark.parametrize("leaf_share", [0.02, 0.6])
def test_otsu_s_cut_between_soil_and_leaves_stays(leaf_share: float) -> None:
    """Leaves a fair share of the pixels, or most of them (a canopy seen from above): Otsu's
    cut lies in the valley, above the soil's spread or below the median, and is kept."""
    rng = np.random.default_rng(8)
    leaves = int(1_000_000 * leaf_share)
    values = np.concatenate(
        [rng.normal(0.0, 0.03, 1_000_000 - leaves), rng.normal(0.5, 0.08, leaves)]
    )
    tally, edges = np.histogram(values, bins=4000, range=(-1.0, 2.0))
    centres = (edges[:-1] + edges[1:]) / 2
    present = tally > 0
    values, weights = centres[present], tally[present].astype(np.int64)
    otsu = otsu_threshold(values, weights)
    assert 0.1 < otsu < 0.4
    assert above_the_soil(values, weights, otsu) == otsu


def test_a_moved_cut_is_said(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where Otsu's cut is moved out of the soil, the station's reading says so (the cut, the
    threshold used); where it is kept, nothing."""
    from devices.camera.frames import KINECT_V2_PAPER
    from fieldapp.io.session import Capture, CaptureImages
    from fieldapp.recon import scans

    rng = np.random.default_rng(9)
    h, w = KINECT_V2_PAPER.height, KINECT_V2_PAPER.width
    color = np.clip(rng.normal((110, 95, 80), 4, (h, w, 3)), 0, 255).astype(np.uint8)
    color[:40, :40] = (60, 140, 40)
    depth = np.full((h, w), 2.0, np.float32)
    frames = [
        scans.frame_of(
            CaptureImages(Capture(station=1, view=0, depth="d", color="c"), depth, color)
        )
    ]
    *_, kept = scans._separation(frames, "otsu")
    assert kept is None
    monkeypatch.setattr(scans, "above_the_soil", lambda values, weights, cut: cut + 0.1)
    *_, tally, moved = scans._separation(frames, "otsu")
    assert tally is not None
    assert moved == otsu_threshold(*exg_values(tally))  # the cut as Otsu made it


@pytest.mark.parametrize(
    ("rgb", "grey"),
    [
        ((139, 149, 138), True),  # a reference sphere in the shade
        ((40, 40, 44), True),  # a dark stand
        ((230, 230, 235), True),  # a white card in the sun
        ((120, 90, 59), False),  # soil, or a tip seen with its colour
        ((189, 174, 107), False),  # pale straw
        ((50, 110, 25), False),  # a leaf
    ],
)
def test_a_group_without_hue_is_grey_whatever_its_brightness(
    rgb: tuple[int, int, int], grey: bool
) -> None:
    colors = np.tile(np.array(rgb, np.uint8), (50, 1))
    colors[:10] = 0  # libfreenect2's holes: not colour, not counted either way
    assert grey_group(colors) is grey


def test_a_group_without_colour_is_not_judged_grey() -> None:
    assert grey_group(np.zeros((20, 3), np.uint8)) is False
    assert grey_group(np.full((20, 3), 10, np.uint8)) is False  # a JPEG's black
