"""The rig opened from settings: simulated devices through their real drivers, one world."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator

import pytest

from devices.base.protocol import BaseState, Pose
from fieldapp.rig import Rig, RigError, open_rig, telemetry_endpoint
from fieldapp.settings import DeviceSettings

from .conftest import HANG_S


def wait_until(predicate: Callable[[], bool], timeout_s: float = HANG_S) -> None:
    deadline_s = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline_s:
            pytest.fail(f"condition not met within {timeout_s} s")
        time.sleep(0.01)


@pytest.fixture
def rig() -> Iterator[Rig]:
    with open_rig(DeviceSettings(), realtime=False) as opened:
        yield opened


def test_all_simulated_devices_say_so(rig: Rig) -> None:
    summaries = {s.name: s for s in rig.devices()}
    assert set(summaries) == {"camera", "table", "base"}
    assert all(s.simulated for s in summaries.values())
    assert rig.simulated
    assert "/dev/pts/" in summaries["table"].where
    assert "tcp://127.0.0.1:" in summaries["base"].where


def test_base_and_table_move_the_one_world(rig: Rig) -> None:
    assert rig.world is not None
    start = rig.world.base_pose()
    assert (start.x_m, start.y_m) == pytest.approx((1.6, 1.6))  # station 5 in the map frame
    status = rig.base.goto("s01", Pose(0.0, 0.0, 0.0), timeout_s=10.0)
    assert status.state is BaseState.ARRIVED
    wait_until(lambda: abs(rig.world.base_pose().x_m - status.pose.x_m) < 1e-9)  # type: ignore[union-attr]
    pose = rig.world.base_pose()
    assert (pose.x_m, pose.y_m) == pytest.approx((0.0, 0.0), abs=0.05)
    assert pose.y_m == pytest.approx(status.pose.y_m, abs=1e-9)
    reached_deg = rig.table.goto_deg(90.0)
    assert reached_deg == pytest.approx(90.0, abs=0.2)
    assert rig.world.table_angle_deg() == pytest.approx(reached_deg, abs=1e-3)
    frame = rig.camera.read_frame()
    assert frame.meta["table_angle_deg"] == pytest.approx(reached_deg, abs=1e-3)
    assert frame.meta["base_pose"].x_m == pytest.approx(status.pose.x_m, abs=1e-9)


def test_close_stops_every_thread_and_socket() -> None:
    before = {t.ident for t in threading.enumerate()}
    rig = open_rig(DeviceSettings(), realtime=False)
    assert rig.table.goto_deg(45.0) == pytest.approx(45.0, abs=0.2)
    rig.close()
    wait_until(lambda: {t.ident for t in threading.enumerate() if t.is_alive()} <= before)
    assert not rig.camera.is_open
    rig.close()  # twice is harmless


def test_a_missing_table_port_is_a_rig_error_with_advice() -> None:
    before = {t.ident for t in threading.enumerate()}
    with pytest.raises(RigError, match=r"table on /nonexistent/tty.*fieldapp table --port"):
        open_rig(DeviceSettings(table_port="/nonexistent/tty"), realtime=False)
    wait_until(lambda: {t.ident for t in threading.enumerate() if t.is_alive()} <= before)


def test_an_unreachable_base_is_a_rig_error_with_advice() -> None:
    settings = DeviceSettings(base_endpoint="tcp://127.0.0.1:9")  # nobody serves port 9
    with pytest.raises(RigError, match=r"base at tcp://127.0.0.1:9: .*fieldapp base --endpoint"):
        open_rig(settings, realtime=False)


def test_telemetry_endpoint_is_the_next_port() -> None:
    assert telemetry_endpoint("tcp://10.0.0.2:5555") == "tcp://10.0.0.2:5556"
    assert telemetry_endpoint("ipc:///tmp/base") is None
