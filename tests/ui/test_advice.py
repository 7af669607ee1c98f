"""Advice follows the error's actual cause: a missing library is told as such (never as a
cable), the typed device errors keep their advice, and the Set-up panel says it is ready
once connected."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from devices.camera import CameraUnavailable
from devices.camera.kinect2 import load_binding
from devices.table import TableDisconnected
from fieldapp.rig import RigError
from ui.advice import advice_for, missing_library
from ui.main_window import MainWindow
from ui.mission.setup_panel import NOT_CONNECTED, READY


def kinect_missing() -> CameraUnavailable:
    try:
        load_binding()
    except CameraUnavailable as error:
        return error
    pytest.skip("pylibfreenect2 is installed here")


def test_a_missing_kinect_driver_is_told_as_not_installed() -> None:
    error = kinect_missing()
    advice = advice_for(error)
    assert advice.startswith("The Kinect v2 driver (pylibfreenect2) is not installed")
    assert "packaging/README.md" in advice
    assert "USB" not in advice and "cable" not in advice
    wrapped = RigError("camera: cannot open")
    wrapped.__cause__ = error
    assert advice_for(wrapped) == advice  # through the rig's error too


@pytest.mark.parametrize(
    ("error", "module"),
    [
        (
            ModuleNotFoundError("No module named 'pyrealsense2'", name="pyrealsense2"),
            "pyrealsense2",
        ),
        (CameraUnavailable("RealSense needs pyrealsense2: pip install it"), "pyrealsense2"),
        (ImportError("No module named 'zmq.backend'"), "zmq"),
        (CameraUnavailable("no Kinect v2 found on USB"), None),
        (TableDisconnected("no answer on /dev/ttyUSB0"), None),
    ],
)
def test_the_missing_library_is_found_in_the_error(
    error: BaseException, module: str | None
) -> None:
    assert missing_library(error) == module


def test_typed_errors_keep_their_own_advice() -> None:
    assert "USB 3 cable" in advice_for(CameraUnavailable("no Kinect v2 found on USB"))
    lost = RigError("table")
    lost.__cause__ = TableDisconnected("no answer")
    assert "table's USB cable" in advice_for(lost)
    assert advice_for(ValueError("plain")) == ""


def test_setup_says_connect_only_while_disconnected(
    make_window: Callable[..., MainWindow], wait_until: Callable[..., bool]
) -> None:
    window = make_window()
    setup = window.pages["mission"].setup  # type: ignore[attr-defined]
    assert setup.result.text() == NOT_CONNECTED
    window.toggle_connection()
    assert wait_until(lambda: window.context.hub.connected)
    assert setup.result.text() == READY
    window.toggle_connection()
    assert wait_until(lambda: not window.context.hub.connected)
    assert setup.result.text() == NOT_CONNECTED


@pytest.mark.usefixtures("qapp")
def test_a_missing_driver_is_told_in_gui_words() -> None:
    from ui.notifications import Notifier

    notifier = Notifier()
    notifier.error("Devices not connected", kinect_missing())
    realsense = "RealSense needs pyrealsense2: pip install 'fieldapp[realsense]'"
    missing = CameraUnavailable(f"{realsense} (No module named 'pyrealsense2')")
    notifier.error("Devices not connected", missing)
    for notice in notifier.history:
        assert "pip" not in notice.message and "pip" not in notice.advice, notice
        assert "packaging/README.md" in notice.advice
    assert "install fieldapp's RealSense support" in notifier.history[1].message
    notifier.deleteLater()


def test_a_table_of_unknown_position_is_mended_in_the_set_up_tab_not_a_terminal() -> None:
    """After a power-up that made the table's position unknown (docs/TABLE.md), the mission's
    advice names the commands; the window says which Set-up buttons do the same."""
    from devices.table import TableStatus
    from fieldapp.mission.control import Gate, MissionFault
    from fieldapp.mission.steps import prepare_table
    from ui.wording import gui_text

    class UnknownTable:
        position_known = False

        def status(self) -> TableStatus:
            return TableStatus("Idle", None, 0.0, False, None)

    with pytest.raises(MissionFault) as refused:
        prepare_table(UnknownTable(), Gate())  # type: ignore[arg-type]
    words = gui_text(refused.value.fault.advice)
    assert "It is at its zero mark, in Mission > Set-up" in words
    assert "Home in Mission > Set-up" in words
    assert "fieldapp" not in words
