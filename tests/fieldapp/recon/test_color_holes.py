"""Colour with holes, as libfreenect2 registers a Kinect v2's: black where the colour camera,
5.2 cm beside the depth camera and with a less high field of view, does not see the depth
pixel. A pixel without colour is neither soil nor plant to the threshold, and green grows into
it along the surface it continues (``scans.grown_into_uncoloured``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from devices.camera.frames import KINECT_V2_PAPER as K
from devices.sim.sensor import COLOR_BASELINE_M, COLOR_CAMERA, registered_as_libfreenect2
from fieldapp.cli import main
from fieldapp.io.images import read_color
from fieldapp.io.session import Capture, CaptureImages
from fieldapp.recon.exg import NO_COLOUR, exg_keys, exg_tally, exg_values, otsu_threshold
from fieldapp.recon.scans import (
    CONTINUOUS_SHARE,
    NOT_MEASURED_M,
    UNCOLOURED_REACH_PX,
    DepthEdges,
    _separation,
    frame_of,
    grown_into_uncoloured,
)

SOIL, LEAF = (120, 90, 60), (50, 140, 30)


def _scene() -> tuple[NDArray[np.float32], NDArray[np.uint8], dict[str, NDArray[np.bool_]]]:
    """Depth and exact colour of soil 1.6 m away, a lower leaf 1.0 m away across the middle
    and an upper leaf 0.7 m away over the lower leaf's left half."""
    depth = np.full((K.height, K.width), 1.6, np.float32)
    parts = {name: np.zeros(depth.shape, bool) for name in ("lower", "upper")}
    parts["lower"][150:260, 120:400] = True
    parts["upper"][180:230, 120:250] = True
    depth[parts["lower"]] = 1.0
    depth[parts["upper"]] = 0.7
    parts["lower"] &= ~parts["upper"]
    color = np.empty((*depth.shape, 3), np.uint8)
    color[:] = SOIL
    color[parts["lower"] | parts["upper"]] = LEAF
    return depth, color, parts


def _black(color: NDArray[np.uint8]) -> NDArray[np.bool_]:
    black: NDArray[np.bool_] = color.sum(axis=2) == 0
    return black


def test_the_colour_camera_misses_rows_at_the_top_and_bottom_and_bands_beside_near_edges() -> None:
    depth, color, parts = _scene()
    holed = registered_as_libfreenect2(color, depth, K)
    black = _black(holed)
    fy_colour, height = COLOR_CAMERA[1], COLOR_CAMERA[5]
    rows = np.arange(K.height)
    outside = np.abs((rows - K.cy) / K.fy) > (height / 2) / fy_colour  # its field is less high
    assert black[outside].all() and 20 < outside[: K.height // 2].sum() < 35
    inside = ~outside
    # beside the upper leaf's right edge the lower leaf is hidden from the colour camera over
    # fx * b * (1 / 0.7 - 1 / 1.0) pixels (the colour camera looks from the left)
    band = K.fx * COLOR_BASELINE_M * (1 / 0.7 - 1 / 1.0)
    shadow = black & parts["lower"] & inside[:, None]
    columns = np.flatnonzero(shadow[200])
    assert columns.min() >= 250 and columns.max() - 249 == pytest.approx(band, abs=2)
    assert not black[parts["upper"]].any()  # the nearest surface keeps its colour
    assert black[inside].mean() < 0.1


def test_green_grows_into_the_hidden_part_of_a_leaf_and_not_into_the_soil() -> None:
    depth, color, parts = _scene()
    holed = registered_as_libfreenect2(color, depth, K)
    black = _black(holed) & np.isfinite(depth)
    green = (holed[..., 1].astype(int) - holed[..., 0] > 40) & ~black
    hidden = black & parts["lower"]
    hidden[:30] = hidden[390:] = False  # the shadow beside the upper leaf, not the rows
    assert hidden.sum() > 300 and not green[hidden].any()  # without colour: not green
    edges = DepthEdges.of(depth, np.isfinite(depth))
    grown = grown_into_uncoloured(green, black, edges)
    assert grown[hidden].mean() > 0.99
    soil = ~(parts["lower"] | parts["upper"])
    assert not grown[soil].any()  # the black soil beside the leaves is behind their edges


def test_pixels_without_colour_are_left_out_of_the_threshold() -> None:
    depth, color, _ = _scene()
    holed = registered_as_libfreenect2(color, depth, K)
    exact = exg_tally(exg_keys(color.reshape(-1, 3)))
    tally = exg_tally(exg_keys(holed.reshape(-1, 3)))
    assert tally.sum() == (~_black(holed)).sum()  # black tallied nowhere
    values, weights = exg_values(tally)
    assert otsu_threshold(values, weights) == pytest.approx(otsu_threshold(*exg_values(exact)))


def test_the_simulator_writes_colour_with_holes_when_asked(tmp_path: Path) -> None:
    out = tmp_path / "holes"
    options = ["--stations", "5", "--views", "0", "--color-holes"]
    assert main(["simulate", "--out", str(out), *options]) == 0
    truth = json.loads((out / "truth.json").read_text())
    assert truth["color_holes"] is True
    session = json.loads((out / "session.json").read_text())
    color = read_color(out / session["captures"][0]["color"])
    assert _black(color)[:10].all() and _black(color)[-10:].all()  # the rows it cannot see
    assert not _black(color)[200].all()


def test_a_station_whose_colour_is_all_black_is_told_by_geometry_for_want_of_colour() -> None:
    depth, color, _ = _scene()
    capture = Capture(station=1, view=0, depth="d.png", color="c.png")
    frames = [frame_of(CaptureImages(capture, depth, np.zeros_like(color)))]
    separation, threshold, weak, _, _, _ = _separation(frames, "otsu")
    assert separation.by_geometry and separation.reason == NO_COLOUR
    assert threshold == weak == np.inf
    holed = registered_as_libfreenect2(color, depth, K)
    frames = [frame_of(CaptureImages(capture, depth, holed))]
    assert not _separation(frames, "otsu")[0].by_geometry  # holes alone leave colour to judge


def test_black_through_a_jpeg_is_still_no_colour() -> None:
    """A JPEG of libfreenect2's black leaves it dark with random hues (sums up to about 30):
    still no colour, so the threshold is the one the same colour without holes gets."""
    import cv2

    def through_jpeg(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
        ok, encoded = cv2.imencode(".jpg", image[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 90])
        assert ok
        decoded: NDArray[np.uint8] = cv2.imdecode(encoded, cv2.IMREAD_COLOR)[..., ::-1]
        return decoded

    depth, color, _ = _scene()
    holed = registered_as_libfreenect2(color, depth, K)
    jpeg = through_jpeg(holed)
    black = _black(holed)
    assert (jpeg[black].astype(int).sum(axis=1) > 6).mean() > 0.01  # not black any more
    tally = exg_tally(exg_keys(jpeg.reshape(-1, 3)))
    assert tally.sum() == pytest.approx((~black).sum(), rel=0.02)
    whole = exg_tally(exg_keys(through_jpeg(color).reshape(-1, 3)))
    assert otsu_threshold(*exg_values(tally)) == pytest.approx(
        otsu_threshold(*exg_values(whole)), abs=0.05
    )


def _grown_by_filters(
    green: NDArray[np.bool_], uncoloured: NDArray[np.bool_], edges: DepthEdges
) -> NDArray[np.bool_]:
    """The straightforward growth: at each step an erosion and a dilation of the whole frame
    give every pixel its nearest and farthest grown neighbour."""
    import cv2

    far = edges.far_m
    tolerance = CONTINUOUS_SHARE * far
    grown = green.copy()
    square = np.ones((3, 3), np.uint8)
    for _ in range(UNCOLOURED_REACH_PX):
        nearest = cv2.erode(np.where(grown, far, NOT_MEASURED_M).astype(np.float32), square)
        farthest = cv2.dilate(np.where(grown, far, 0.0).astype(np.float32), square)
        continues = (np.abs(far - nearest) <= tolerance) | (np.abs(far - farthest) <= tolerance)
        wider = grown | (uncoloured & continues)
        if np.array_equal(wider, grown):
            break
        grown = wider
    return grown


@pytest.mark.parametrize("seed", range(6))
def test_growing_into_black_takes_the_pixels_filters_over_the_whole_frame_take(seed: int) -> None:
    """Surfaces at steps of 1-10 % of their distance (some continuous, some not), pixels
    unmeasured, green and black at random up to the frame's edges: the growth that judges
    only the pixels beside the last grown ones takes the same pixels, bit for bit."""
    rng = np.random.default_rng(seed)
    shape = (70, 90)
    blocks = rng.choice([1.0, 1.02, 1.05, 1.1], size=(7, 9))
    depth = (1.6 * np.kron(blocks, np.ones((10, 10)))).astype(np.float32)
    depth += rng.normal(0.0, 0.004, shape).astype(np.float32)
    measured = rng.random(shape) > 0.05
    green = (rng.random(shape) < 0.08) & measured
    uncoloured = (rng.random(shape) < 0.6) & measured & ~green
    edges = DepthEdges.of(depth, measured)
    expected = _grown_by_filters(green, uncoloured, edges)
    grown = grown_into_uncoloured(green, uncoloured, edges)
    assert grown.shape == shape and np.array_equal(grown, expected)
    assert expected.sum() > green.sum() + 100  # it grew, and stopped somewhere
    assert not expected[uncoloured].all()
