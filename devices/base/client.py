"""The application's driver for the mobile base (fieldapp-base/1 client).

``BaseClient`` is handed its :class:`~devices.base.transport.BaseTransport` and never opens a
socket; :func:`open_base` makes the transport from endpoints (and keys) and the client on it.
The client sends each request through the transport's Lazy Pirate with its
:class:`ClientTiming`, keeps the base's watchdog fed with ``heartbeat`` every 0.25 s while a goal
is active (a background thread), and re-emits the transport's telemetry, if it carries any, as
psygnal signals. ``goto`` blocks until ``arrived`` (or raises), or with ``wait=False`` returns at
once; :meth:`BaseClient.follow_goal` is a generator yielding each status until the goal ends.
"""

from __future__ import annotations

import itertools
import logging
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from types import TracebackType
from typing import Any

from psygnal import Signal

from devices.base.channel import RetryPolicy
from devices.base.errors import (
    BaseError,
    BaseRequestRejected,
    BaseStopped,
    LinkClosed,
    NavigationFailed,
)
from devices.base.keys import ClientKeys
from devices.base.protocol import (
    BaseState,
    Command,
    ErrorCode,
    Pose,
    ProtocolError,
    Request,
    Status,
    encode_request,
)
from devices.base.transport import BaseTransport, Context, open_transport

log = logging.getLogger(__name__)

CLIENT_NAME = "fieldapp 0.1"


@dataclass(frozen=True)
class BaseInfo:
    """The ``hello`` result."""

    name: str
    protocol: int
    frame: str
    bounds_m: tuple[float, float, float, float]
    session: str | None = None
    """Changes at every start of the base; ``None`` from an older base."""


@dataclass(frozen=True)
class ClientTiming:
    """Each request's Lazy Pirate (``request_timeout_s`` per try, ``retries`` more tries, run by
    the transport), the heartbeat period during a goal, and the status poll of ``goto``."""

    request_timeout_s: float = 0.5
    retries: int = 2
    heartbeat_period_s: float = 0.25
    status_poll_period_s: float = 0.1


def _error_for(cmd: Command, code: ErrorCode, message: str) -> BaseError:
    if code is ErrorCode.STOPPED:
        return BaseStopped(f"base is stopped: {message}", code.value)
    if code is ErrorCode.NAV_FAILED:
        return NavigationFailed(f"navigation failed: {message}", code.value)
    return BaseRequestRejected(f"{cmd.value} refused ({code.value}): {message}", code.value)


class BaseClient:
    """Drives one base through ``transport``, which it closes with itself. Thread-safe;
    signals fire on the transport's telemetry thread."""

    pose_received = Signal(float, Pose)
    """(base clock t_s, pose) from ``pose`` telemetry."""
    state_received = Signal(Status)

    def __init__(self, transport: BaseTransport, *, timing: ClientTiming | None = None) -> None:
        self.timing = timing or ClientTiming()
        self._policy = RetryPolicy(self.timing.request_timeout_s, self.timing.retries)
        self._transport = transport
        if transport.carries_telemetry:
            transport.subscribe(self.pose_received.emit, self.state_received.emit)
        self._id_prefix = uuid.uuid4().hex[:12]
        self._counter = itertools.count(1)
        self._base_session: str | None = None
        self._active_goal: str | None = None
        self._sent_goals: set[str] = set()
        self._link_error: BaseError | None = None
        self._closed = threading.Event()
        self._goal_event = threading.Event()
        self._goal_lock = threading.RLock()
        self._heartbeat = threading.Thread(target=self._beat, name="base-heartbeat", daemon=True)
        self._heartbeat.start()

    @property
    def endpoint(self) -> str:
        return self._transport.endpoint

    @property
    def link_error(self) -> BaseError | None:
        """Why background heartbeats failed during the current goal, if they did."""
        return self._link_error

    # --- commands ---

    def hello(self) -> BaseInfo:
        """Greet the base and learn its ``session``, sent with every later request."""
        self._base_session = None
        result = self._request(Command.HELLO, {"client": CLIENT_NAME})
        try:
            xmin, ymin, xmax, ymax = (float(v) for v in result["bounds"])
            session = result.get("session")
            info = BaseInfo(
                str(result["name"]),
                int(result["protocol"]),
                str(result["frame"]),
                (xmin, ymin, xmax, ymax),
                None if session is None else str(session),
            )
        except (KeyError, TypeError, ValueError) as error:
            raise BaseRequestRejected(f"malformed hello result from the base: {error}") from None
        self._base_session = info.session
        return info

    def status(self) -> Status:
        status = self._status_from(self._request(Command.STATUS, {}))
        if self._active_goal is not None and status.state is not BaseState.MOVING:
            self._end_goal()
        return status

    def goto(
        self, goal_id: str, goal: Pose, *, wait: bool = True, timeout_s: float = 300.0
    ) -> Status:
        """Send the base to ``goal`` (map frame); block until arrival unless ``wait`` is False.

        Raises :class:`BaseStopped` (latched), :class:`NavigationFailed` (aborted, refused,
        cancelled or not arrived within ``timeout_s``), :class:`BaseOffline`, and
        :class:`BaseRequestRejected` with code ``stale_session`` when the base restarted since
        this client's ``hello`` (sent first when there was none).
        """
        if self._base_session is None:
            self.hello()
        self._sent_goals.add(goal_id)  # before sending: a request may arrive after all
        self._request(Command.GOTO, {"goal_id": goal_id, **goal.to_json()})
        self._begin_goal(goal_id)
        if not wait:
            return self.status()
        statuses = self.follow_goal(goal_id, timeout_s)
        last = next(statuses)
        for last in statuses:  # noqa: B007 (the last one is the result)
            pass
        return last

    def follow_goal(self, goal_id: str, timeout_s: float = 300.0) -> Iterator[Status]:
        """Yield the status every poll period until ``goal_id`` arrives; raise if it does not."""
        deadline_s = time.monotonic() + timeout_s
        while True:
            if self._link_error is not None:
                raise self._link_error
            status = self.status()
            yield status
            if status.goal_id == goal_id and status.state is BaseState.ARRIVED:
                return
            _raise_if_over(status, goal_id)
            if time.monotonic() > deadline_s:
                self.cancel(goal_id)
                raise NavigationFailed(
                    f"goal {goal_id} not reached within {timeout_s:g} s: cancelled"
                )
            time.sleep(self.timing.status_poll_period_s)

    def sent_goal(self, goal_id: str) -> bool:
        """Whether this client sent a ``goto`` with ``goal_id``, answered or not: a request
        whose reply was lost (the base hung, the link dropped) may still have reached the
        base and started it, after the client had given up on it."""
        return goal_id in self._sent_goals

    def cancel(self, goal_id: str) -> bool:
        cancelled = bool(self._request(Command.CANCEL, {"goal_id": goal_id}).get("cancelled"))
        self._end_goal()
        return cancelled

    def stop(self) -> None:
        """Zero velocity now and set the base's stop latch."""
        self._end_goal()
        self._request(Command.STOP, {})

    def reset(self) -> None:
        """Clear the stop latch (never starts motion)."""
        self._request(Command.RESET, {})

    def heartbeat(self) -> None:
        self._request(Command.HEARTBEAT, {})

    # --- internals ---

    def _request(self, cmd: Command, args: dict[str, Any]) -> dict[str, Any]:
        request_id = f"{self._id_prefix}-{next(self._counter):06d}"
        request = Request(request_id, cmd, args, self._base_session)
        try:
            data = encode_request(request)
        except ValueError as error:
            raise BaseRequestRejected(
                f"{cmd.value}: arguments are not finite JSON ({error})"
            ) from None
        reply = self._transport.request(request.id, data, self._policy)
        if reply.ok:
            return reply.result or {}
        code = reply.error_code or ErrorCode.BAD_REQUEST
        if code is ErrorCode.STALE_SESSION:
            self._base_session = None  # the next goto greets the restarted base first
        raise _error_for(cmd, code, reply.error_message or "")

    @staticmethod
    def _status_from(result: dict[str, Any]) -> Status:
        try:
            return Status.from_json(result)
        except ProtocolError as error:
            raise BaseRequestRejected(f"malformed status from the base: {error.message}") from None

    def _begin_goal(self, goal_id: str) -> None:
        with self._goal_lock:
            self._link_error = None
            self._active_goal = goal_id
            self._goal_event.set()

    def _end_goal(self) -> None:
        with self._goal_lock:
            self._active_goal = None
            self._goal_event.clear()

    def _beat(self) -> None:
        while not self._closed.is_set():
            if not self._goal_event.wait(timeout=0.1) or self._closed.is_set():
                continue
            goal = self._active_goal
            try:
                self.heartbeat()
            except LinkClosed:
                return  # closed during the beat: nothing failed
            except BaseError as error:
                self._heartbeat_failed(goal, error)
            self._closed.wait(self.timing.heartbeat_period_s)

    def _heartbeat_failed(self, goal: str | None, error: BaseError) -> None:
        """A heartbeat sent during ``goal`` failed: that goal's link is lost. When another
        goal has begun meanwhile (the failure was the link's before it, reported to a beat
        that waited its turn), the new goal's own beats decide."""
        with self._goal_lock:
            if goal is None or self._active_goal != goal:
                log.info("heartbeat of goal %s failed after it ended: %s", goal, error)
                return
            log.warning("heartbeat failed during goal %s: %s", goal, error)
            self._link_error = error
            self._active_goal = None
            self._goal_event.clear()

    def close(self) -> None:
        """Stop heartbeats and close the transport (the base is not told): a request still
        waiting for its reply, a beat's or a caller's, ends at once with :class:`LinkClosed`."""
        self._closed.set()
        self._goal_event.set()  # wakes the heartbeat thread, which sees it is closed
        self._transport.close()
        self._heartbeat.join(timeout=5.0)
        self._end_goal()

    def __enter__(self) -> BaseClient:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def open_base(
    endpoint: str,
    telemetry_endpoint: str | None = None,
    *,
    keys: ClientKeys | None = None,
    timing: ClientTiming | None = None,
    context: Context | None = None,
    clock: Callable[[], float] = time.monotonic,
) -> BaseClient:
    """A client of the base at ``endpoint`` (subscribed to ``telemetry_endpoint`` if given).

    Over ``tcp://`` (CURVE with ``keys``; loopback only without, else :class:`InsecureEndpoint`)
    the client has its own ZeroMQ context; an in-process base on ``inproc://`` is reached
    through its ``context``. ``clock`` times each request's tries (``timing``; a fake clock in
    tests). Nothing is sent yet (call :meth:`BaseClient.hello`).
    """
    transport = open_transport(
        endpoint, telemetry_endpoint, keys=keys, context=context, clock=clock
    )
    try:
        return BaseClient(transport, timing=timing)
    except BaseException:
        transport.close()
        raise


def _raise_if_over(status: Status, goal_id: str) -> None:
    """Raise when ``goal_id`` ended without arriving."""
    if status.state is BaseState.STOPPED:
        raise BaseStopped(
            f"base stopped during goal {goal_id}: {status.error}", ErrorCode.STOPPED.value
        )
    if status.state is BaseState.ABORTED:
        raise NavigationFailed(
            f"goal {goal_id} aborted: {status.error}", ErrorCode.NAV_FAILED.value
        )
    if status.goal_id != goal_id or status.state is not BaseState.MOVING:
        raise NavigationFailed(f"goal {goal_id} is no longer active (state {status.state.value})")
