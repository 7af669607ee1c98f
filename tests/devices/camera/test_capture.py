"""Quiet captures: the per-pixel median, missing pixels, and the noise it removes."""

from __future__ import annotations

import numpy as np
import pytest

from devices.camera.capture import capture_median, combine_frames, median_depth_m
from devices.camera.frames import Frame
from devices.camera.sim import SimCamera
from devices.sim.world import SimWorld

NAN = np.nan


def test_median_ignores_missing_and_keeps_majority_missing_pixels_missing() -> None:
    stack = np.array(
        [
            [1.0, 1.0, NAN, 2.0],
            [3.0, NAN, NAN, 4.0],
            [2.0, NAN, NAN, NAN],
            [9.0, NAN, 5.0, NAN],
            [4.0, 2.0, NAN, NAN],
        ],
        np.float32,
    ).reshape(5, 1, 4)
    median = median_depth_m(stack)[0]
    assert median[0] == pytest.approx(3.0)  # 1 2 3 4 9
    assert np.isnan(median[1])  # valid in 2 of 5: missing in most
    assert np.isnan(median[2])  # valid in 1 of 5
    assert np.isnan(median[3])  # valid in 2 of 5


def test_median_of_even_count_averages_the_middle_pair() -> None:
    stack = np.array([[1.0, NAN], [2.0, 7.0], [4.0, NAN], [8.0, 5.0]], np.float32).reshape(4, 1, 2)
    median = median_depth_m(stack)[0]
    assert median[0] == pytest.approx(3.0)
    assert median[1] == pytest.approx(6.0)  # 2 of 4 valid is not "most missing"


def test_combine_frames_takes_colour_and_ir_medians_and_last_timestamp() -> None:
    frames = [
        Frame(
            np.full((2, 2), d, np.float32),
            np.full((2, 2, 3), c, np.uint8),
            np.full((2, 2), i, np.uint16),
            timestamp_s=t,
            meta={"frame_number": t},
        )
        for d, c, i, t in [(1.0, 10, 100, 1), (3.0, 250, 50, 2), (2.0, 20, 70, 3)]
    ]
    combined = combine_frames(frames)
    assert np.all(combined.depth_m == 2.0)
    assert np.all(combined.color == 20)
    assert combined.ir is not None and np.all(combined.ir == 70)
    assert combined.timestamp_s == 3
    assert combined.meta["frames_combined"] == 3 and combined.meta["first_timestamp_s"] == 1


def test_capture_rejects_no_frames() -> None:
    blank = Frame(np.zeros((1, 1), np.float32), np.zeros((1, 1, 3), np.uint8))
    with pytest.raises(ValueError, match="n >= 1"):
        capture_median(lambda timeout_s: blank, 0, 1.0)


def _plane_errors_mm(frame: Frame, truth_m: np.ndarray, far_from_edges: np.ndarray) -> np.ndarray:
    both = np.isfinite(frame.depth_m) & far_from_edges
    return 1000.0 * (frame.depth_m[both] - truth_m[both])


def test_capture_of_five_has_visibly_lower_depth_noise(
    flat_world: SimWorld, flat_truth: tuple[np.ndarray, np.ndarray]
) -> None:
    """Against a noise-free render: RMS depth error of one frame vs the median of 5."""
    truth, far = flat_truth  # within the crop radius, away from edges
    assert far.sum() > 50_000
    with SimCamera(flat_world, seed=11) as camera:
        single = camera.read_frame()
        quiet = camera.capture(5)
    rms_one = float(np.sqrt(np.mean(_plane_errors_mm(single, truth, far) ** 2)))
    rms_five = float(np.sqrt(np.mean(_plane_errors_mm(quiet, truth, far) ** 2)))
    # Kinect v2 noise at 1.5-2.5 m is 1.5-3 mm; the median of 5 Gaussian samples has
    # sqrt(pi / 10) = 0.56 of the spread of one
    assert 1.0 < rms_one < 4.0
    assert rms_five < 0.7 * rms_one
    assert rms_five > 0.4 * rms_one  # a median of 5, not the noise-free truth
    # dropouts that flicker are not filled in: the quiet frame misses about as much as one
    assert abs(np.isnan(quiet.depth_m).mean() - np.isnan(single.depth_m).mean()) < 0.01
