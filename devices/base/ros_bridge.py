"""Robot-side bridge: serves fieldapp-base/1 on the robot and drives ROS 1 navigation.

Goals become ``move_base`` action goals (frame ``map``), ``cancel``/``stop``/lost link cancel the
action and publish zero velocity on ``/cmd_vel``; the pose comes from ``/amcl_pose``. The
protocol, reply cache, stop latch and watchdog are the shared :class:`ProtocolServer` and
:class:`BaseController`; ROS is reached only through the small :class:`NavigationBackend`
interface, so all of this is tested with a fake backend and no ROS.

Install note (on the robot, e.g. the DashgoB1's computer). ROS is not on PyPI and this package
needs Python >= 3.11, while ROS Noetic's system Python is 3.8. Either

* RoboStack: ``mamba create -n base -c conda-forge -c robostack-staging python=3.11
  ros-noetic-rospy ros-noetic-actionlib ros-noetic-move-base-msgs ros-noetic-geometry-msgs
  ros-noetic-sensor-msgs``, then ``pip install -e /path/to/fieldapp``; or
* system Noetic: a Python 3.11 venv with ``pip install -e /path/to/fieldapp rospkg catkin_pkg``
  and ``PYTHONPATH=/opt/ros/noetic/lib/python3/dist-packages`` (rospy and the message packages
  are pure Python).

Then, with ``roscore``, ``move_base`` and ``amcl`` running::

    python -m devices.base.ros_bridge --keys ~/.fieldapp/base-keys \\
        --bind tcp://*:5555 --telemetry tcp://*:5556 --bounds -2 -2 12 12

Without ``--keys`` only loopback addresses are accepted. With keys the bridge fails closed (no
client gets in while its ZAP handler is not running), re-reads ``authorized_clients/`` every
second and at once on ``kill -HUP`` (a removed key's requests are dropped, also on connections
already made), logs every rejected handshake with the client's public key, gives ``hello`` a new
``session`` at every start (a captured ``goto`` cannot be replayed after a restart), caches
replies per client and never swallows a ``stop``, and lets only the client that sent the goal
feed the lost-link watchdog. After a lost link it stays stopped until a client sends ``reset``.
"""

from __future__ import annotations

import argparse
import logging
import math
import signal
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Protocol

from devices.base.backend import BackendSnapshot, NavProgress
from devices.base.controller import BaseController, ControllerConfig
from devices.base.keys import ServerKeys
from devices.base.protocol import Goal, Pose
from devices.base.server import ProtocolServer

log = logging.getLogger(__name__)

UNKNOWN_BATTERY_PCT = -1.0
"""Reported when no battery topic is configured (the spec has no 'unknown' value)."""
ZERO_VELOCITY_HOLD_S = 0.5
"""After a halt, zero velocity is re-published this long to override in-flight commands."""


class NavigationBackend(Protocol):
    """The ROS side, as the bridge needs it."""

    def send_goal(self, goal: Goal) -> None: ...

    def cancel_goal(self) -> None: ...

    def publish_zero_velocity(self) -> None: ...

    def goal_progress(self) -> tuple[NavProgress, str | None]:
        """Progress of the last goal and, when aborted, why."""
        ...

    def current_pose(self) -> Pose: ...

    def battery_pct(self) -> float: ...


class BridgeBackend:
    """Adapts a :class:`NavigationBackend` to the server's motion backend."""

    def __init__(
        self, navigation: NavigationBackend, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.navigation = navigation
        self._clock = clock
        self._goal_active = False
        self._hold_until_s = -math.inf

    def begin_goal(self, goal: Goal) -> None:
        self._hold_until_s = -math.inf
        self.navigation.send_goal(goal)
        self._goal_active = True

    def halt(self) -> None:
        if self._goal_active:
            self.navigation.cancel_goal()
            self._goal_active = False
        self.navigation.publish_zero_velocity()
        self._hold_until_s = self._clock() + ZERO_VELOCITY_HOLD_S

    def update(self) -> BackendSnapshot:
        if self._clock() < self._hold_until_s:
            self.navigation.publish_zero_velocity()
        progress, error = self.navigation.goal_progress()
        if not self._goal_active and progress is NavProgress.MOVING:
            progress = NavProgress.IDLE  # cancelled, the action server has not caught up yet
        if progress is not NavProgress.MOVING:
            self._goal_active = False
        pose, battery = self.navigation.current_pose(), self.navigation.battery_pct()
        return BackendSnapshot(pose, progress, battery, error)


class RosNavigation:
    """:class:`NavigationBackend` on rospy + actionlib (move_base, /cmd_vel, /amcl_pose)."""

    def __init__(self, battery_topic: str | None = None) -> None:
        import actionlib
        import rospy
        from actionlib_msgs.msg import GoalStatus  # type: ignore[import-not-found]
        from geometry_msgs.msg import PoseWithCovarianceStamped, Twist
        from move_base_msgs.msg import MoveBaseAction

        self._rospy: Any = rospy
        self._status: Any = GoalStatus
        self._twist: Any = Twist
        self._lock = threading.Lock()
        self._pose = Pose(0.0, 0.0, 0.0)
        self._battery_pct = UNKNOWN_BATTERY_PCT
        self._has_goal = False
        self._client: Any = actionlib.SimpleActionClient("move_base", MoveBaseAction)
        if not self._client.wait_for_server(rospy.Duration(10.0)):
            raise RuntimeError("move_base action server not available after 10 s")
        self._cmd_vel: Any = rospy.Publisher("/cmd_vel", Twist, queue_size=1)
        rospy.Subscriber("/amcl_pose", PoseWithCovarianceStamped, self._on_amcl_pose)
        if battery_topic:
            from sensor_msgs.msg import BatteryState  # type: ignore[import-not-found]

            rospy.Subscriber(battery_topic, BatteryState, self._on_battery)

    def _on_amcl_pose(self, message: Any) -> None:
        p, q = message.pose.pose.position, message.pose.pose.orientation
        yaw_deg = math.degrees(
            math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
        )
        with self._lock:
            self._pose = Pose(float(p.x), float(p.y), yaw_deg)

    def _on_battery(self, message: Any) -> None:
        if math.isfinite(message.percentage):
            self._battery_pct = 100.0 * float(message.percentage)

    def send_goal(self, goal: Goal) -> None:
        from move_base_msgs.msg import MoveBaseGoal

        target = MoveBaseGoal()
        target.target_pose.header.frame_id = "map"
        target.target_pose.header.stamp = self._rospy.Time.now()
        target.target_pose.pose.position.x = goal.pose.x_m
        target.target_pose.pose.position.y = goal.pose.y_m
        half_yaw_rad = math.radians(goal.pose.yaw_deg) / 2.0
        target.target_pose.pose.orientation.z = math.sin(half_yaw_rad)
        target.target_pose.pose.orientation.w = math.cos(half_yaw_rad)
        self._client.send_goal(target)
        self._has_goal = True

    def cancel_goal(self) -> None:
        self._client.cancel_all_goals()

    def publish_zero_velocity(self) -> None:
        self._cmd_vel.publish(self._twist())

    def goal_progress(self) -> tuple[NavProgress, str | None]:
        if not self._has_goal:
            return NavProgress.IDLE, None
        state, status = self._client.get_state(), self._status
        if state in (status.PENDING, status.ACTIVE):
            return NavProgress.MOVING, None
        if state == status.SUCCEEDED:
            return NavProgress.ARRIVED, None
        if state in (status.ABORTED, status.REJECTED):
            text = self._client.get_goal_status_text() or "move_base gave up"
            return NavProgress.ABORTED, str(text)
        return NavProgress.IDLE, None

    def current_pose(self) -> Pose:
        with self._lock:
            return self._pose

    def battery_pct(self) -> float:
        return self._battery_pct


def build_bridge(
    navigation: NavigationBackend,
    command_endpoint: str,
    telemetry_endpoint: str,
    keys: ServerKeys | None,
    config: ControllerConfig,
    clock: Callable[[], float] = time.monotonic,
) -> ProtocolServer:
    """The protocol server over ``navigation`` (not started); ``clock`` times the watchdog,
    telemetry and the zero-velocity hold."""
    controller = BaseController(BridgeBackend(navigation, clock), config)
    return ProtocolServer(controller, command_endpoint, telemetry_endpoint, keys, clock=clock)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the bridge as a ROS node until ROS shuts down."""
    parser = argparse.ArgumentParser(prog="python -m devices.base.ros_bridge")
    parser.add_argument("--bind", default="tcp://127.0.0.1:5555")
    parser.add_argument("--telemetry", default="tcp://127.0.0.1:5556")
    parser.add_argument(
        "--keys", type=Path, help="folder with base.key_secret, authorized_clients/"
    )
    parser.add_argument("--bounds", type=float, nargs=4, default=[-10.0, -10.0, 10.0, 10.0])
    parser.add_argument("--watchdog", type=float, default=1.0, help="seconds")
    parser.add_argument("--battery-topic", help="a sensor_msgs/BatteryState topic")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    import rospy

    keys = ServerKeys.from_dir(args.keys) if args.keys else None
    rospy.init_node("fieldapp_base_bridge", disable_signals=False)
    config = ControllerConfig("ros-bridge", tuple(args.bounds), args.watchdog)
    server = build_bridge(
        RosNavigation(args.battery_topic), args.bind, args.telemetry, keys, config
    )
    server.start()
    signal.signal(signal.SIGHUP, lambda _signum, _frame: server.reload_keys())
    try:
        rospy.spin()
    finally:
        server.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
