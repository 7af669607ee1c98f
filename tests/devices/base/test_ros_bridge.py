"""The ROS bridge's protocol and watchdog logic over real sockets, with ROS replaced by a fake."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from devices.base import BaseClient, BaseState, BaseStopped, NavigationFailed, Pose
from devices.base.backend import NavProgress
from devices.base.controller import ControllerConfig
from devices.base.protocol import Command, Goal
from devices.base.ros_bridge import ZERO_VELOCITY_HOLD_S, BridgeBackend, build_bridge
from devices.base.server import ProtocolServer

from ..fake_clock import FakeClock

MakeClient = Callable[..., BaseClient]
WaitFor = Callable[[Callable[[], bool], float], float]


class FakeNavigation:
    """Records what the bridge asks of ROS; the test plays move_base."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self.goals: list[Goal] = []
        self.cancels = 0
        self.zero_velocity_times_s: list[float] = []
        self.progress = NavProgress.IDLE
        self.error: str | None = None
        self.pose = Pose(1.0, 2.0, 30.0)
        self._lock = threading.Lock()

    def send_goal(self, goal: Goal) -> None:
        self.goals.append(goal)
        self.progress = NavProgress.MOVING

    def cancel_goal(self) -> None:
        self.cancels += 1
        self.progress = NavProgress.IDLE  # actionlib: PREEMPTED

    def publish_zero_velocity(self) -> None:
        self.zero_velocity_times_s.append(self.clock())

    def goal_progress(self) -> tuple[NavProgress, str | None]:
        return self.progress, self.error

    def current_pose(self) -> Pose:
        return self.pose

    def battery_pct(self) -> float:
        return 76.5


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


@pytest.fixture
def bridge(clock: FakeClock) -> Iterator[tuple[FakeNavigation, ProtocolServer]]:
    navigation = FakeNavigation(clock)
    config = ControllerConfig("ros-bridge", (-2.0, -2.0, 12.0, 12.0), 1.0)
    server = build_bridge(navigation, "tcp://127.0.0.1:*", "tcp://127.0.0.1:*", None, config, clock)
    server.start()
    yield navigation, server
    server.close()


def test_goto_becomes_a_move_base_goal_and_arrival_is_reported(
    bridge: tuple[FakeNavigation, ProtocolServer], make_client: MakeClient, wait_for: WaitFor
) -> None:
    navigation, server = bridge
    client = make_client(server.command_endpoint)
    assert client.hello().bounds_m == (-2.0, -2.0, 12.0, 12.0)
    client.goto("s05", Pose(1.6, 1.6, 0.0), wait=False)
    assert navigation.goals == [Goal("s05", Pose(1.6, 1.6, 0.0))]
    status = client.status()
    assert status.state is BaseState.MOVING
    assert status.pose == Pose(1.0, 2.0, 30.0)
    assert status.battery_pct == 76.5
    navigation.pose = Pose(1.62, 1.59, 0.8)
    navigation.progress = NavProgress.ARRIVED
    wait_for(lambda: client.status().state is BaseState.ARRIVED, 20.0)
    assert client.status().pose == Pose(1.62, 1.59, 0.8)
    threading.Timer(0.3, lambda: setattr(navigation, "progress", NavProgress.ARRIVED)).start()
    assert client.goto("s06", Pose(3.0, 1.6, 90.0), timeout_s=5.0).state is BaseState.ARRIVED
    assert navigation.cancels == 0


def test_lost_link_cancels_the_goal_and_holds_zero_velocity(
    bridge: tuple[FakeNavigation, ProtocolServer],
    clock: FakeClock,
    make_client: MakeClient,
    make_link: Callable[[str], Any],
    wait_for: WaitFor,
) -> None:
    navigation, server = bridge
    link = make_link(server.command_endpoint)
    client = make_client(link.endpoint)
    client.goto("s01", Pose(5.0, 5.0, 0.0), wait=False)
    for _ in range(3):  # heartbeats keep it alive past the watchdog period
        beats = server.controller.executed[Command.HEARTBEAT]
        clock.advance(0.5)
        wait_for(lambda beats=beats: server.controller.executed[Command.HEARTBEAT] > beats, 20.0)
    assert navigation.cancels == 0
    link.blackhole = True
    clock.advance(1.0)  # at most the watchdog period since the last request: not yet
    time.sleep(0.1)
    assert navigation.cancels == 0
    clock.advance(1.0)
    wait_for(lambda: navigation.cancels == 1, 20.0)
    assert server.status().state is BaseState.STOPPED
    assert server.status().error == "link lost"
    zero_s = navigation.zero_velocity_times_s
    halted_s = zero_s[0]  # published at once
    for step in range(1, 5):  # and again during the hold
        clock.advance(0.1)
        wait_for(lambda step=step: zero_s[-1] > halted_s + 0.1 * step - 0.05, 20.0)
    clock.advance(0.2)  # past the hold: no more
    time.sleep(0.1)
    assert max(zero_s) < halted_s + ZERO_VELOCITY_HOLD_S
    link.blackhole = False
    assert client.status().error == "link lost"
    with pytest.raises(BaseStopped):
        client.goto("s02", Pose(1.0, 1.0, 0.0))
    assert len(navigation.goals) == 1
    client.reset()
    client.goto("s02", Pose(1.0, 1.0, 0.0), wait=False)
    assert len(navigation.goals) == 2


def test_aborted_navigation_is_reported_with_move_base_text(
    bridge: tuple[FakeNavigation, ProtocolServer], make_client: MakeClient
) -> None:
    navigation, server = bridge
    client = make_client(server.command_endpoint)

    def give_up() -> None:
        navigation.error = "Failed to find a valid plan"
        navigation.progress = NavProgress.ABORTED

    threading.Timer(0.3, give_up).start()
    with pytest.raises(NavigationFailed, match="Failed to find a valid plan"):
        client.goto("s03", Pose(4.0, 4.0, 0.0), timeout_s=5.0)


def test_stop_and_cancel_reach_ros(
    bridge: tuple[FakeNavigation, ProtocolServer], make_client: MakeClient
) -> None:
    navigation, server = bridge
    client = make_client(server.command_endpoint)
    client.goto("s04", Pose(4.0, 4.0, 0.0), wait=False)
    assert client.cancel("s04") is True
    assert navigation.cancels == 1
    assert len(navigation.zero_velocity_times_s) >= 1
    client.goto("s05", Pose(4.0, 4.0, 0.0), wait=False)
    client.stop()
    assert navigation.cancels == 2
    assert server.status().state is BaseState.STOPPED


def test_navigation_dropping_the_goal_counts_as_aborted() -> None:
    navigation = FakeNavigation()
    backend = BridgeBackend(navigation)
    backend.begin_goal(Goal("g", Pose(1.0, 0.0, 0.0)))
    assert backend.update().progress is NavProgress.MOVING
    navigation.progress = NavProgress.IDLE  # preempted by someone else on the robot
    assert backend.update().progress is NavProgress.IDLE


def test_the_bridge_obeys_only_the_goal_s_owner_and_its_session(
    bridge: tuple[FakeNavigation, ProtocolServer],
    clock: FakeClock,
    make_client: MakeClient,
    wait_for: WaitFor,
) -> None:
    navigation, server = bridge
    owner = make_client(server.command_endpoint)
    assert owner.hello().session == server.session
    owner.goto("s01", Pose(5.0, 5.0, 0.0), wait=False)
    owner.close()  # the commanding workstation dies
    watcher = make_client(server.command_endpoint)
    for _ in range(4):  # another client polling does not feed the watchdog
        clock.advance(0.3)
        watcher.status()
    wait_for(lambda: navigation.cancels == 1, 20.0)
    assert server.status().error == "link lost"
    watcher.reset()  # recovery only by a client's explicit reset and a new goto
    assert len(navigation.goals) == 1
