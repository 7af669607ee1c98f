"""The base's protocol state: commands, goal state, stop latch and lost-link watchdog.

No I/O and no clock of its own: :class:`BaseController` is given each request, the client it
came from and the time, and is ticked with the backend's snapshot. The socket side lives in
``server.py``. The ``session`` value is new for every controller (every start of the base):
requests carrying another one are refused (except ``stop``, which halting makes always safe to
execute), and ``goto`` needs it, so a captured request cannot be replayed against a restarted
base. Only the client that sent the active goal (its
:data:`ClientId`) feeds the lost-link watchdog.
"""

from __future__ import annotations

import logging
import secrets
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from devices.base.backend import GoalRefused, MotionBackend, NavProgress
from devices.base.protocol import (
    PROTOCOL_VERSION,
    BaseState,
    Command,
    ErrorCode,
    Pose,
    Reply,
    Request,
    Status,
    goal_from_args,
)

log = logging.getLogger(__name__)

LINK_LOST = "link lost"
STOP_REQUESTED = "stop requested"

ClientId = tuple[bytes, bytes]
"""Who sent a request: (the client's CURVE public key in Z85, or b"" without keys; the
connection's routing id, which fieldapp's client keeps across its reconnections). The
watchdog is fed by any request on the connection that sent the goal, and by a ``heartbeat``
with the goal's key on any connection: a client that opens a new socket for each retry (the
Lazy Pirate of the ZeroMQ guide; the spec's identity is the key) keeps its goal across a lost
reply, while another process with the same key polling ``status`` (a ``fieldapp base
status`` beside the app) does not keep a dead app's goal going. Without keys a connection is
the only identity there is. The reply cache is keyed by the key alone where there is one
(the server's)."""
ANONYMOUS: ClientId = (b"", b"")


@dataclass(frozen=True)
class ControllerConfig:
    name: str = "fieldapp-base"
    bounds_m: tuple[float, float, float, float] = (-10.0, -10.0, 10.0, 10.0)
    """Map bounds ``(xmin, ymin, xmax, ymax)`` in metres."""
    watchdog_s: float = 1.0


class BaseController:
    """Executes validated requests against a backend, exactly as the spec says."""

    def __init__(self, backend: MotionBackend, config: ControllerConfig | None = None) -> None:
        self.backend = backend
        self.config = config or ControllerConfig()
        self.executed: Counter[Command] = Counter()
        self._state = BaseState.IDLE
        self._goal_id: str | None = None
        self._error: str | None = None
        self._latched = False
        self._last_heard_s = 0.0
        self._owner: ClientId | None = None
        self.session = secrets.token_hex(8)
        """Changes every time the base starts (a new controller)."""
        self._snapshot = backend.update()
        self._handlers: dict[Command, Callable[[dict[str, Any]], Reply | dict[str, Any]]] = {
            Command.HELLO: self._hello,
            Command.GOTO: self._goto,
            Command.CANCEL: self._cancel,
            Command.STOP: self._stop,
            Command.RESET: self._reset,
            Command.STATUS: lambda _args: self.status().to_json(),
            Command.HEARTBEAT: lambda _args: {},
        }

    @property
    def latched(self) -> bool:
        return self._latched

    def status(self) -> Status:
        snap = self._snapshot
        return Status(self._state, self._goal_id, snap.pose, snap.battery_pct, self._error)

    @property
    def pose(self) -> Pose:
        return self._snapshot.pose

    def handle(self, request: Request, now_s: float, client: ClientId = ANONYMOUS) -> Reply:
        """Execute one request from ``client`` (once: the reply cache is the server's job)."""
        refusal = self._session_problem(request)
        if refusal is not None:
            log.warning("%s %s refused: %s", request.cmd, request.id, refusal.error_message)
            return Reply(request.id, False, None, refusal.error_code, refusal.error_message)
        if self._feeds_watchdog(client, request.cmd):
            self._last_heard_s = now_s
        self.executed[request.cmd] += 1
        outcome = self._handlers[request.cmd](request.args)
        if request.cmd is Command.GOTO and not isinstance(outcome, Reply):
            self._owner, self._last_heard_s = client, now_s
        if isinstance(outcome, Reply):
            return Reply(
                request.id, outcome.ok, outcome.result, outcome.error_code, outcome.error_message
            )
        return Reply.success(request.id, outcome)

    def _feeds_watchdog(self, client: ClientId, cmd: Command) -> bool:
        """Whether a request from ``client`` is heard from the goal's owner (see ``ClientId``)."""
        owner = self._owner
        if owner is None or client == owner:
            return owner is not None
        return cmd is Command.HEARTBEAT and bool(owner[0]) and client[0] == owner[0]

    def _session_problem(self, request: Request) -> Reply | None:
        if request.cmd is Command.STOP:
            return None  # a stop is always executed: halting never does harm
        if request.cmd is Command.HELLO:
            return None  # a greeting learns the new session; replayed, it changes nothing
        if request.session is not None and request.session != self.session:
            return Reply.failure(
                None, ErrorCode.STALE_SESSION, "the base restarted since hello: send hello again"
            )
        if request.session is None and request.cmd is Command.GOTO:
            return Reply.failure(
                None, ErrorCode.BAD_REQUEST, "goto needs the base's session: send hello first"
            )
        return None

    def tick(self, now_s: float) -> None:
        """Take the backend's news and run the watchdog."""
        self._snapshot = self.backend.update()
        if self._state is not BaseState.MOVING:
            return
        if now_s - self._last_heard_s > self.config.watchdog_s:
            log.warning(
                "no request for %.2f s during goal %s: stopping",
                now_s - self._last_heard_s,
                self._goal_id,
            )
            self._halt_and_latch(LINK_LOST)
            return
        progress = self._snapshot.progress
        if progress is NavProgress.ARRIVED:
            self._state = BaseState.ARRIVED
        elif progress in (NavProgress.ABORTED, NavProgress.IDLE):
            self._state = BaseState.ABORTED
            self._error = self._snapshot.error or "navigation dropped the goal"
            log.warning("goal %s aborted: %s", self._goal_id, self._error)

    def _halt_and_latch(self, reason: str) -> None:
        self.backend.halt()
        self._snapshot = self.backend.update()
        self._latched = True
        self._state = BaseState.STOPPED
        self._error = reason

    def _hello(self, _args: dict[str, Any]) -> dict[str, Any]:
        return {
            "name": self.config.name,
            "protocol": PROTOCOL_VERSION,
            "session": self.session,
            "frame": "map",
            "bounds": list(self.config.bounds_m),
        }

    def _goto(self, args: dict[str, Any]) -> Reply | dict[str, Any]:
        goal = goal_from_args(args)
        problem = self._bounds_problem(goal.pose)  # a goal off the map is so in any state
        if problem:
            return Reply.failure(None, ErrorCode.OUT_OF_BOUNDS, problem)
        if self._latched:
            return Reply.failure(
                None, ErrorCode.STOPPED, f"stop latch set ({self._error}): send reset, then goto"
            )
        if self._state is BaseState.MOVING:
            return Reply.failure(
                None, ErrorCode.BUSY, f"goal {self._goal_id} is active: cancel it first"
            )
        try:
            self.backend.begin_goal(goal)
        except GoalRefused as error:
            return Reply.failure(None, ErrorCode.NAV_FAILED, str(error))
        self._state, self._goal_id, self._error = BaseState.MOVING, goal.goal_id, None
        log.info("goal %s accepted: %s", goal.goal_id, goal.pose)
        return {"accepted": True}

    def _bounds_problem(self, pose: Pose) -> str | None:
        xmin, ymin, xmax, ymax = self.config.bounds_m
        if not xmin <= pose.x_m <= xmax:
            return f"x={pose.x_m:g} outside the map [{xmin:g}, {xmax:g}]"
        if not ymin <= pose.y_m <= ymax:
            return f"y={pose.y_m:g} outside the map [{ymin:g}, {ymax:g}]"
        return None

    def _cancel(self, args: dict[str, Any]) -> dict[str, Any]:
        if self._state is not BaseState.MOVING or args["goal_id"] != self._goal_id:
            return {"cancelled": False}
        self.backend.halt()
        self._snapshot = self.backend.update()
        self._state = BaseState.IDLE
        return {"cancelled": True}

    def _stop(self, _args: dict[str, Any]) -> dict[str, Any]:
        self._halt_and_latch(STOP_REQUESTED)
        return {}

    def _reset(self, _args: dict[str, Any]) -> dict[str, Any]:
        if self._latched:
            self._latched = False
            self._state, self._error = BaseState.IDLE, None
        return {}
