"""The live preview on a simulated Kinect v2 stream: frames shown without blocking, the
reading under the cursor against the simulated world, quality figures, freeze, save, IR,
the 3D view (or its clear absence offscreen) and a stream that ends."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
import shiboken6

from devices.camera.frames import Frame
from devices.camera.sim import SimCamera
from devices.camera.stream import FrameStream
from devices.geometry import Matrix4
from devices.sim.world import SimWorld
from fieldapp.io.images import read_depth_units
from fieldapp.settings import Settings
from ui.context import AppContext
from ui.devices.hub import DeviceHub
from ui.live.cloud_view import opengl_problem
from ui.live.frame_math import cloud_points, read_pixel
from ui.live.preview import LivePreview
from ui.notifications import Notifier
from ui.state import UiState

pytestmark = pytest.mark.usefixtures("no_leaks")

Wait = Callable[..., bool]


@pytest.fixture(scope="module")
def world() -> SimWorld:
    return SimWorld.default()


@pytest.fixture
def stream(no_leaks: None, world: SimWorld) -> Iterator[FrameStream]:
    camera = SimCamera(world, realtime=True)
    camera.open()
    stream = FrameStream(camera, timeout_s=1.0).start()
    yield stream
    stream.stop()
    camera.close()


@pytest.fixture
def make_preview(
    no_leaks: None, settings: Settings, tmp_path: Path
) -> Iterator[Callable[[], LivePreview]]:
    """Builds live previews; each is shut down and deleted after the test (the factory keeps
    no reference, so nothing outlives the test)."""
    made: list[tuple[LivePreview, AppContext]] = []

    def make() -> LivePreview:
        context = AppContext(settings, DeviceHub(), Notifier(), UiState(tmp_path / "ui.ini"))
        widget = LivePreview(context)
        widget.resize(1000, 700)
        widget.show()
        made.append((widget, context))
        return widget

    yield make
    for widget, context in made:
        widget.shutdown()
        widget.close()
        for obj in (widget, context.hub, context.notifier):
            shiboken6.delete(obj)
    made.clear()


def test_frames_are_shown_with_rates_and_quality(
    make_preview: Callable[[], LivePreview],
    stream: FrameStream,
    world: SimWorld,
    wait_until: Wait,
    never_within: Wait,
) -> None:
    preview = make_preview()
    preview.attach(stream, world.intrinsics)
    assert wait_until(lambda: preview.frames_shown >= 10, 10.0)
    image = preview.images.depth_item.image
    assert image is not None and image.shape == (424, 512)
    low, high = preview.images.colour_bar.levels()  # Auto: the scene's depth percentiles
    assert 0.3 < low < high < 8.0 and (low, high) == preview.images.levels_m
    assert wait_until(
        lambda: "camera" in preview.stream_label.text() and "fps" in preview.stream_label.text()
    )
    assert wait_until(lambda: "Ready to capture" in preview.quality_verdict.text(), 5.0)
    assert all("✔" in value.text() for _, value in preview.quality_values)
    preview.freeze.setChecked(True)
    frozen = preview.frames_shown
    assert never_within(lambda: preview.frames_shown > frozen, 0.4)
    preview.freeze.setChecked(False)
    assert wait_until(lambda: preview.frames_shown > frozen, 2.0)


def field_point(T_field_camera: Matrix4, point_m: tuple[float, float, float]) -> np.ndarray:
    return T_field_camera[:3, :3] @ np.array(point_m) + T_field_camera[:3, 3]


def test_cursor_reading_lies_on_the_simulated_soil(
    make_preview: Callable[[], LivePreview], stream: FrameStream, world: SimWorld, wait_until: Wait
) -> None:
    preview = make_preview()
    preview.attach(stream, world.intrinsics)
    assert wait_until(lambda: preview.frame is not None, 10.0)
    frame = preview.frame
    assert frame is not None
    T = np.asarray(frame.meta["T_field_camera"])
    for u, v in ((256, 400), (100, 380), (420, 390)):  # the soil in front of the rig
        preview.show_reading(u, v)
        assert f"pixel ({u}, {v})" in preview.readout.text()
        reading = read_pixel(frame.depth_m, world.intrinsics, u, v)
        assert reading is not None and reading.point_m is not None
        assert f"depth {reading.depth_m:.3f} m" in preview.readout.text()
        x, y, z = field_point(T, reading.point_m)
        assert z == pytest.approx(
            world.scene.soil.height_m(np.array([x]), np.array([y]))[0], abs=0.03
        )
    assert read_pixel(frame.depth_m, world.intrinsics, 600, 10) is None  # outside the image


def test_save_writes_the_shown_frame(
    make_preview: Callable[[], LivePreview],
    stream: FrameStream,
    world: SimWorld,
    wait_until: Wait,
    tmp_path: Path,
) -> None:
    preview = make_preview()
    preview.attach(stream, world.intrinsics)
    assert wait_until(lambda: preview.frame is not None, 10.0)
    preview.freeze.setChecked(True)
    frame = preview.frame
    assert frame is not None
    preview.save_to(tmp_path / "frames")
    assert wait_until(lambda: not preview.saving, 10.0)
    depth_files = list((tmp_path / "frames").glob("*-depth.png"))
    assert len(depth_files) == 1 and len(list((tmp_path / "frames").iterdir())) == 4
    depth_m = read_depth_units(depth_files[0]).astype(np.float64) / 1000.0
    valid = np.isfinite(frame.depth_m)
    assert np.abs(depth_m[valid] - frame.depth_m[valid]).max() <= 0.0006
    assert (depth_m[~valid] == 0).all()


def test_ir_beside_depth(
    make_preview: Callable[[], LivePreview], stream: FrameStream, world: SimWorld, wait_until: Wait
) -> None:
    preview = make_preview()
    preview.attach(stream, world.intrinsics)
    assert wait_until(lambda: preview.frame is not None, 10.0)
    preview.second_view.setCurrentText("IR")
    shown = preview.images.second_item.image
    assert shown is not None and shown.shape == (424, 512) and shown.dtype == np.uint8
    assert 0 < shown.mean() < 255
    preview.second_view.setCurrentText("Colour")
    assert preview.images.second_item.image.shape == (424, 512, 3)
    preview.second_view.setCurrentText("None")
    assert not preview.images.second_plot.isVisible()


def test_3d_view_or_a_clear_reason(
    make_preview: Callable[[], LivePreview], stream: FrameStream, world: SimWorld, wait_until: Wait
) -> None:
    preview = make_preview()
    preview.attach(stream, world.intrinsics)
    assert wait_until(lambda: preview.cloud.points_shown > 1000, 10.0)
    if opengl_problem() is None:
        assert preview.cloud.available
    else:  # the offscreen platform has no OpenGL: the view says so
        assert not preview.cloud.available
        label = preview.cloud.findChild(type(preview.readout), "cloudUnavailable")
        assert label is not None and "3D view unavailable" in label.text()


def test_cloud_points_follow_the_pinhole_model(world: SimWorld) -> None:
    depth = np.full((424, 512), 2.0, np.float32)
    depth[:, :256] = np.nan
    frame = Frame(depth, np.full((424, 512, 3), 255, np.uint8))
    points, colours = cloud_points(frame, world.intrinsics, step=4)
    assert len(points) == 106 * 64  # the right half, every 4th pixel
    assert np.allclose(points[:, 1], 2.0)  # forward is the depth
    k = world.intrinsics
    assert points[:, 0].min() == pytest.approx((256 - k.cx) / k.fx * 2.0, abs=1e-5)
    assert np.allclose(colours, 1.0)


def test_a_stream_that_ends_is_reported(
    make_preview: Callable[[], LivePreview], world: SimWorld, wait_until: Wait, tmp_path: Path
) -> None:
    preview = make_preview()
    from devices.camera.replay import ReplayCamera
    from fieldapp.cli.simulate import write_session

    about = {"scene": "plot", "seed": 0, "day": 0}
    write_session(tmp_path / "short", world, [5], [0, 1], 0, about)  # two frames, then the end
    camera = ReplayCamera(tmp_path / "short", loop=False, fps=10.0)
    camera.open()
    stream = FrameStream(camera, timeout_s=0.5).start()
    try:
        preview.attach(stream, camera.intrinsics)
        assert wait_until(lambda: "Stream ended" in preview.stream_label.text(), 10.0)
        assert preview.frames_shown >= 1
        notices = preview.context.notifier.history
        assert [n.title for n in notices] == ["Live camera"]
        assert "end of its session" in notices[0].advice
        assert not preview.timer.isActive() and not preview.monitor.running
    finally:
        stream.stop()
        camera.close()


def test_depth_colour_indices_follow_the_fixed_levels() -> None:
    from ui.live.frame_math import depth_indices, depth_lut

    depth = np.array([[np.nan, 0.2, 0.5, 2.5, 4.5, 9.0]], np.float32)
    indices = depth_indices(depth, 0.5, 4.5)
    assert indices.tolist() == [[0, 1, 1, 128, 255, 255]]
    lut = depth_lut(np.full((255, 3), 200, np.uint8))
    assert lut.shape == (256, 4) and tuple(lut[0]) == (0, 0, 0, 255)
    assert (lut[1:, :3] == 200).all() and (lut[:, 3] == 255).all()


def test_nothing_is_decoded_or_painted_while_the_preview_is_not_seen(
    make_preview: Callable[[], LivePreview], stream: FrameStream, world: SimWorld, wait_until: Wait
) -> None:
    preview = make_preview()
    preview.attach(stream, world.intrinsics)
    assert wait_until(lambda: preview.frames_shown >= 2, 10.0)
    assert preview.displaying and preview.monitor.running

    preview.hide()  # another page shown
    assert not preview.displaying and not preview.monitor.running
    preview.show()
    assert preview.displaying and preview.monitor.running
    shown = preview.frames_shown
    assert wait_until(lambda: preview.frames_shown > shown, 10.0)

    preview.showMinimized()  # the window minimised: still "visible" to Qt, not to anyone
    assert wait_until(lambda: not preview.displaying, 5.0)
    assert not preview.monitor.running
    preview.showNormal()
    assert wait_until(lambda: preview.displaying, 5.0) and preview.monitor.running

    preview.hide()
    preview.attach(stream, world.intrinsics)  # a new rig while hidden: still nothing shown
    assert not preview.displaying and not preview.monitor.running
    preview.show()
    assert preview.displaying


def test_the_live_page_stops_when_another_page_is_shown(
    make_window: Callable[..., object], wait_until: Wait
) -> None:
    from ui.main_window import MainWindow

    window = make_window()
    assert isinstance(window, MainWindow)
    window.show_page("live")
    live = window.pages["live"]
    preview = live if isinstance(live, LivePreview) else live.findChild(LivePreview)
    assert isinstance(preview, LivePreview)
    window.toggle_connection()
    assert wait_until(lambda: preview.frames_shown >= 1, 20.0)
    window.show_page("mission")
    assert not preview.displaying and not preview.monitor.running
    window.show_page("live")
    assert preview.displaying
