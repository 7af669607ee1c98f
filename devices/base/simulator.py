"""The simulated mobile base: the motion model served over the real protocol on loopback
(``tcp://127.0.0.1``), or in process on ``inproc://`` endpoints of a shared ZeroMQ context.

``time_scale`` makes simulated motion faster than real time (tests) or equal to it (demos); the
watchdog and telemetry periods follow the link's ``clock`` (real time by default; tests inject a
fake clock and advance it). The current
pose is :attr:`SimulatedBase.pose` and the psygnal signal :attr:`SimulatedBase.on_pose` (emitted
from the server thread when the pose changes), for the simulated world to follow.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Callable
from enum import StrEnum
from types import TracebackType

import zmq
from psygnal import Signal

from devices.base.backend import BackendSnapshot
from devices.base.controller import BaseController, ControllerConfig
from devices.base.keys import ServerKeys
from devices.base.motion import MotionFault, MotionLimits, MotionModel
from devices.base.protocol import Command, Goal, Pose, Status
from devices.base.server import ProtocolServer, ServerTiming

log = logging.getLogger(__name__)

DEFAULT_COMMAND_ENDPOINT = "tcp://127.0.0.1:5555"
DEFAULT_TELEMETRY_ENDPOINT = "tcp://127.0.0.1:5556"
DEFAULT_BOUNDS_M = (-5.0, -5.0, 5.0, 5.0)


class SimFault(StrEnum):
    BLOCKED_PATH = "blocked_path"
    """The base stops on its way; navigation gives up after the blocked timeout (aborted)."""
    NAV_FAILURE = "nav_failure"
    """No plan: the goal is aborted shortly after it is accepted."""
    FREEZE = "freeze"
    """The base's computer hangs: no replies, no telemetry, no motion."""
    CRASH = "crash"
    """The base's process dies: sockets gone at once."""


class SimulatedMotionBackend:
    """A :class:`MotionModel` advanced by the wall clock times ``time_scale``."""

    def __init__(
        self, model: MotionModel, time_scale: float, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.model = model
        self.time_scale = time_scale
        self._clock = clock
        self._last_s = clock()

    def begin_goal(self, goal: Goal) -> None:
        self.model.set_goal(goal.pose)

    def halt(self) -> None:
        self.model.halt()

    def update(self) -> BackendSnapshot:
        now_s = self._clock()
        self.model.step((now_s - self._last_s) * self.time_scale, idle_speedup=self.time_scale)
        self._last_s = now_s
        model = self.model
        return BackendSnapshot(model.pose, model.progress, model.battery_pct, model.error)


class SimulatedBase:
    """A base that serves fieldapp-base/1 on loopback (or with CURVE keys anywhere)."""

    on_pose = Signal(Pose)

    def __init__(
        self,
        command_endpoint: str = DEFAULT_COMMAND_ENDPOINT,
        telemetry_endpoint: str = DEFAULT_TELEMETRY_ENDPOINT,
        *,
        keys: ServerKeys | None = None,
        time_scale: float = 1.0,
        seed: int = 0,
        start: Pose | None = None,
        limits: MotionLimits | None = None,
        bounds_m: tuple[float, float, float, float] = DEFAULT_BOUNDS_M,
        watchdog_s: float = 1.0,
        timing: ServerTiming | None = None,
        clock: Callable[[], float] = time.monotonic,
        context: zmq.Context[zmq.Socket[bytes]] | None = None,
    ) -> None:
        """``clock`` times the link (watchdog, telemetry); motion follows the real clock.
        ``context``: serve on this ZeroMQ context, left open (an in-process base on
        ``inproc://`` endpoints, reached by ``open_base(..., context=context)``)."""
        self.model = MotionModel(limits, start, seed)
        self.backend = SimulatedMotionBackend(self.model, time_scale)
        config = ControllerConfig("fieldapp-sim-base", bounds_m, watchdog_s)
        self.controller = BaseController(self.backend, config)
        self.server = ProtocolServer(
            self.controller, command_endpoint, telemetry_endpoint, keys, timing, clock, context
        )
        self.server.on_tick = self._emit_pose
        self._last_pose = self.model.pose

    def start(self) -> SimulatedBase:
        self.server.start()
        return self

    def close(self) -> None:
        self.server.close()

    def __enter__(self) -> SimulatedBase:
        return self.start()

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def command_endpoint(self) -> str:
        return self.server.command_endpoint

    @property
    def telemetry_endpoint(self) -> str:
        return self.server.telemetry_endpoint

    @property
    def pose(self) -> Pose:
        return self.model.pose

    @property
    def latched(self) -> bool:
        return self.controller.latched

    @property
    def executed(self) -> Counter[Command]:
        """How many times each command was executed (cached replies do not count)."""
        return self.controller.executed

    def status(self) -> Status:
        return self.server.status()

    def inject_fault(self, fault: SimFault) -> None:
        log.warning("injecting fault %s", fault)
        if fault is SimFault.FREEZE:
            self.server.freeze()
        elif fault is SimFault.CRASH:
            self.server.crash()
        else:
            self.model.faults.add(MotionFault(fault.value))

    def clear_faults(self) -> None:
        """Clear motion faults and unfreeze (a crash is final)."""
        self.model.faults.clear()
        self.server.freeze(False)

    def _emit_pose(self, status: Status) -> None:
        if status.pose != self._last_pose:
            self._last_pose = status.pose
            self.on_pose.emit(status.pose)
