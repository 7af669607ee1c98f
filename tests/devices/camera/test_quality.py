"""Capture quality measures against frames built with known defects."""

from __future__ import annotations

import numpy as np
import pytest

from devices.camera.frames import Frame, Intrinsics
from devices.camera.quality import QualityThresholds, assess, flying_pixels, range_m
from devices.camera.sim import SimCamera
from devices.sim.world import SimWorld

CAMERA = Intrinsics(200, 100, 100.0, 100.0, 100.0, 50.0)


def _frame(depth_m: np.ndarray, level: int = 120, timestamp_s: float = 10.0) -> Frame:
    color = np.full((*depth_m.shape, 3), level, np.uint8)
    return Frame(depth_m.astype(np.float32), color, timestamp_s=timestamp_s)


def test_range_is_distance_from_the_optical_centre() -> None:
    depth = np.full((100, 200), 2.0, np.float32)
    distance = range_m(depth, CAMERA)
    assert distance[50, 100] == pytest.approx(2.0)
    assert distance[50, 0] == pytest.approx(2.0 * np.sqrt(2.0))  # 45 degrees off axis


def test_fill_rate_counts_holes_inside_the_crop_region_only() -> None:
    depth = np.full((100, 200), 1.5, np.float32)
    depth[:, 150:] = 3.0  # beyond the 2.25 m radius: not part of the crop region
    depth[:20, :] = np.nan  # the sky: missing, outside the region
    depth[40:50, 40:60] = np.nan  # a 200-pixel dropout inside the region
    report = assess(_frame(depth), CAMERA, now_s=10.0)
    region = 80 * 150
    assert report.fill_rate == pytest.approx((region - 200) / region)
    assert report.crop_fraction == pytest.approx(region / (100 * 200))
    assert report.flying_ratio == 0.0


def test_flying_pixels_between_two_surfaces_are_counted() -> None:
    depth = np.full((100, 200), 1.0, np.float32)
    depth[:, 100:] = 2.0
    rows = np.arange(10, 90, 2)
    depth[rows, 100] = 1.5  # mixed pixels, halfway
    depth[5, 100] = 2.0005  # on the far surface within noise: not mixed
    flags = flying_pixels(depth, QualityThresholds())
    assert set(zip(*np.nonzero(flags), strict=True)) == {(r, 100) for r in rows}
    report = assess(_frame(depth), CAMERA, now_s=10.0)
    near = int((range_m(depth, CAMERA) <= 2.25).sum())
    assert report.flying_ratio == pytest.approx(len(rows) / near)


def test_exposure_and_age_and_the_go_no_go() -> None:
    depth = np.full((100, 200), 1.5, np.float32)
    frame = _frame(depth, level=120, timestamp_s=9.0)
    frame.color[:10] = 255  # 10 % over-exposed
    frame.color[10:40] = 2  # 30 % under-exposed
    limits = QualityThresholds()
    report = assess(frame, CAMERA, limits, now_s=10.0)
    assert report.overexposed == pytest.approx(0.1)
    assert report.underexposed == pytest.approx(0.3)
    assert report.age_s == pytest.approx(1.0)
    problems = report.problems(limits)
    assert [p.split(" ")[0] for p in problems] == ["over-exposed", "under-exposed", "frame"]
    assert not report.ok(limits)
    assert assess(_frame(depth), CAMERA, limits, now_s=10.1).ok(limits)


def test_a_covered_lens_fails() -> None:
    report = assess(_frame(np.full((100, 200), np.nan)), CAMERA, now_s=10.0)
    assert report.fill_rate == 0.0 and report.crop_fraction == 0.0
    assert "crop region" in report.problems(QualityThresholds())[0]


def test_the_simulated_plot_passes(flat_world: SimWorld) -> None:
    with SimCamera(flat_world) as camera:
        frame = camera.read_frame()
    now_s = frame.timestamp_s + 0.03
    report = assess(frame, camera.intrinsics, now_s=now_s)
    assert report.ok(QualityThresholds()), report.problems(QualityThresholds())
    assert 0.97 < report.fill_rate <= 1.0
    assert report.flying_ratio < 0.01
    assert 0.3 < report.crop_fraction < 0.9  # the ground beyond 2.25 m is outside the crop
