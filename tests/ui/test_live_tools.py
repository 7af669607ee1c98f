"""The Live page's tools from issue 25: the depth colour range follows the scene (its depth
percentiles) unless the operator sets it (spin boxes or the histogram's band), a histogram of
the depths, the 3D distance between two clicked points, and images that fill their area
(side by side or one above the other, on the window's background, not black).

Frames here are synthetic planes with known geometry, shown without a camera stream."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from PySide6 import QtCore, QtGui
from pytestqt.qtbot import QtBot

from devices.camera.frames import Frame, Intrinsics
from ui.live.frame_math import (
    auto_levels_m,
    best_arrangement,
    depth_histogram,
    pick_point,
    valid_depths_m,
)
from ui.live.preview import LivePreview

from .test_live import make_preview  # noqa: F401 - the fixture

K = Intrinsics(width=512, height=424, fx=365.0, fy=365.0, cx=256.0, cy=212.0)


def plane_frame(depth_m: float = 2.0, seed: int = 0, holes: bool = True) -> Frame:
    """A wall at ``depth_m`` with a 1 m-deep box in its middle and missing pixels."""
    rng = np.random.default_rng(seed)
    depth = np.full((424, 512), depth_m, np.float32)
    depth[150:270, 200:310] = depth_m - 1.0
    if holes:
        depth[rng.random(depth.shape) < 0.05] = np.nan
    colour = np.full((424, 512, 3), 120, np.uint8)
    return Frame(depth, colour)


def shown(make: Callable[[], LivePreview], frame: Frame) -> LivePreview:
    preview = make()
    preview.intrinsics = K
    preview.show_frame(frame)
    return preview


def test_auto_range_follows_the_depth_percentiles() -> None:
    for seed in (0, 1, 2):
        depths = valid_depths_m(plane_frame(2.5, seed).depth_m)
        low, high = auto_levels_m(depths) or (0.0, 0.0)
        assert (low, high) == pytest.approx((1.5, 2.5), abs=1e-6)  # box front to wall
    stray = np.concatenate([np.full(1000, 2.0, np.float32), np.float32([0.1, 7.9])])
    assert auto_levels_m(stray) == pytest.approx((1.975, 2.025))  # a flat scene: 5 cm wide
    assert auto_levels_m(np.empty(0, np.float32)) is None
    edges, counts = depth_histogram(depths, (0.0, 8.0), 80)
    assert len(edges) == 81 and counts.sum() == depths.size
    assert counts[np.searchsorted(edges, 2.55) - 1] > counts[np.searchsorted(edges, 1.55) - 1] > 0


def test_the_colour_range_is_automatic_until_set_by_hand(
    make_preview: Callable[[], LivePreview],  # noqa: F811
) -> None:
    preview = shown(make_preview, plane_frame(3.0))
    assert preview.depth_range.auto.isChecked()
    assert preview.images.levels_m == pytest.approx((2.0, 3.0))
    assert (preview.low_m.value(), preview.high_m.value()) == pytest.approx((2.0, 3.0))
    assert preview.depth_range.band.getRegion() == pytest.approx((2.0, 3.0))
    _x, curve_y = preview.depth_range.curve.getData()
    assert curve_y is not None and curve_y.sum() == valid_depths_m(plane_frame(3.0).depth_m).size
    preview.show_frame(plane_frame(1.5))  # the scene changes: the range follows
    assert preview.images.levels_m == pytest.approx((0.5, 1.5))

    preview.high_m.setValue(4.0)  # the operator's range: Auto goes off, the range stays
    assert not preview.depth_range.auto.isChecked()
    assert preview.images.levels_m == pytest.approx((0.5, 4.0))
    assert preview.images.colour_bar.levels() == pytest.approx((0.5, 4.0))
    preview.show_frame(plane_frame(3.0))
    assert preview.images.levels_m == pytest.approx((0.5, 4.0))

    preview.depth_range.band.setRegion((1.0, 2.0))  # dragging the band on the histogram
    preview.depth_range.band.sigRegionChangeFinished.emit(preview.depth_range.band)
    assert preview.images.levels_m == pytest.approx((1.0, 2.0))
    assert (preview.low_m.value(), preview.high_m.value()) == pytest.approx((1.0, 2.0))
    preview.depth_range.auto.setChecked(True)  # back to Auto: at once, on the shown frame
    assert preview.images.levels_m == pytest.approx((2.0, 3.0))


def test_the_distance_between_two_picked_points_is_in_3d_metres(
    make_preview: Callable[[], LivePreview],  # noqa: F811
) -> None:
    preview = shown(make_preview, plane_frame(2.0, holes=False))
    preview.pick(256, 212)  # the box's front at 1 m, on the optical axis
    assert len(preview.picks) == 1 and "second point" in preview.distance_label.text()
    preview.pick(256 + 50, 212)  # 50 px right, still on the box: 50 / 365 * 1 m
    assert f"distance A-B: {50 / 365:.3f} m" in preview.distance_label.text()
    preview.pick(256, 212)  # a third pick starts a new pair
    preview.pick(400, 212)  # the wall behind, 2 m deep and 144 / 365 * 2 m to the right
    expected = np.hypot(144 / 365 * 2.0, 1.0)
    assert f"distance A-B: {expected:.3f} m" in preview.distance_label.text()
    scatter, line = preview.images.marks[0]
    assert scatter.data["x"].tolist() == [256.5, 400.5]
    assert line.getData()[0] is not None and len(line.getData()[0]) == 2
    preview.clear_picks()
    assert preview.picks == [] and len(scatter.data) == 0


def test_a_click_on_the_image_picks_its_pixel(
    make_preview: Callable[[], LivePreview],  # noqa: F811
    wait_until: Callable[..., bool],
) -> None:
    preview = shown(make_preview, plane_frame(2.0, holes=False))
    assert wait_until(lambda: preview.images.depth_plot.vb.viewRect().width() > 100)
    view = preview.images
    for u, v in ((256, 212), (100, 50)):
        scene_point = view.depth_plot.vb.mapViewToScene(QtCore.QPointF(u + 0.5, v + 0.5))
        widget_point = view.mapFromScene(scene_point)
        QtBot.mouseClick(view.viewport(), QtCore.Qt.MouseButton.LeftButton, pos=widget_point)
    assert wait_until(lambda: len(preview.picks) == 2)
    picked = np.array([(p.u, p.v) for p in preview.picks])  # within the screen's rounding
    assert np.abs(picked - [(256, 212), (100, 50)]).max() <= 1
    QtBot.mouseClick(view.viewport(), QtCore.Qt.MouseButton.RightButton, pos=widget_point)
    assert wait_until(lambda: preview.picks == [])


def test_a_pick_on_a_hole_takes_the_nearest_measured_pixel() -> None:
    depth = np.full((424, 512), 2.0, np.float32)
    depth[100:103, 100:103] = np.nan
    depth[100, 104] = 1.0  # nearer in the image than any other measured pixel to (101, 101)?
    reading = pick_point(depth, K, 101, 101)
    assert reading is not None and (reading.u, reading.v) in {
        (101, 99),
        (99, 101),
        (101, 103),
        (103, 101),
    }
    assert pick_point(depth, K, 101, 101, radius=1) is None
    assert pick_point(depth, K, 600, 10) is None


def test_the_images_fill_their_area_keeping_aspect(
    make_preview: Callable[[], LivePreview],  # noqa: F811
    wait_until: Callable[..., bool],
) -> None:
    preview = shown(make_preview, plane_frame(2.0))
    panel = preview.images
    panel.setMinimumSize(0, 0)
    panel.setParent(None)  # on its own, so its size is the one set here
    panel.show()
    try:  # wide, tall, and wide again (a range that grew at each resize would shrink them)
        for size, expected in (((1200, 420), "row"), ((560, 900), "column"), ((1200, 420), "row")):
            panel.resize(*size)
            assert wait_until(lambda e=expected: panel.arrangement == e)
            _kind, scale = best_arrangement((size[0] - 90, size[1]), (512, 424), 2)
            w, h = (512, 2 * 424) if expected == "row" else (2 * 512, 424)  # the other way
            assert scale > 1.3 * min((size[0] - 90) / w, size[1] / h)
            for plot in (panel.depth_plot, panel.second_plot):  # each image at least this large
                assert wait_until(lambda p=plot, s=scale: _shown_width_px(p) >= 0.85 * s * 512)
        background = panel.backgroundBrush().color()
        assert background != QtGui.QColor("black")
        assert background == panel.palette().color(QtGui.QPalette.ColorRole.Window)
    finally:
        panel.close()
        panel.deleteLater()


def _shown_width_px(plot: object) -> float:
    box = plot.vb  # type: ignore[attr-defined]
    pixels_per_unit = box.width() / max(box.viewRect().width(), 1e-9)
    return pixels_per_unit * 512
