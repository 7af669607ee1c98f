"""The fieldapp-base/1 wire protocol (``shared/spec/base-protocol.md``): messages, JSON, validation.

Pure encoding and decoding, no I/O. Every request and reply is one frame of UTF-8 JSON; telemetry
is a topic frame then a JSON frame. Decoding a request never raises anything but
:class:`ProtocolError`, whose ``code`` is the spec's error code and ``request_id`` the request's
id when it could be read (so the server can still answer it).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

PROTOCOL_VERSION = 1
MAX_MESSAGE_BYTES = 65536
"""ZMQ_MAXMSGSIZE on the base; larger frames are dropped."""
MAX_ID_CHARS = 128
MAX_SESSION_CHARS = 64
MAX_ABS_COORDINATE = 1.0e6
"""Numbers beyond this (metres or degrees) are rejected as ``bad_request``, not as off the map."""

TOPIC_POSE = b"pose"
TOPIC_STATE = b"state"


class ErrorCode(StrEnum):
    BAD_REQUEST = "bad_request"
    UNKNOWN_COMMAND = "unknown_command"
    OUT_OF_BOUNDS = "out_of_bounds"
    STOPPED = "stopped"
    BUSY = "busy"
    NAV_FAILED = "nav_failed"
    VERSION = "version"
    STALE_SESSION = "stale_session"


class Command(StrEnum):
    HELLO = "hello"
    GOTO = "goto"
    CANCEL = "cancel"
    STOP = "stop"
    RESET = "reset"
    STATUS = "status"
    HEARTBEAT = "heartbeat"


class BaseState(StrEnum):
    IDLE = "idle"
    MOVING = "moving"
    ARRIVED = "arrived"
    ABORTED = "aborted"
    STOPPED = "stopped"


class ProtocolError(Exception):
    """A message that breaks the protocol; ``code`` is the reply's error code."""

    def __init__(self, code: ErrorCode, message: str, request_id: str | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.message = message
        self.request_id = request_id


@dataclass(frozen=True)
class Pose:
    """A planar pose in the map frame: metres and degrees."""

    x_m: float
    y_m: float
    yaw_deg: float

    def to_json(self) -> dict[str, float]:
        return {"x": self.x_m, "y": self.y_m, "yaw_deg": self.yaw_deg}

    @classmethod
    def from_json(cls, value: Any, where: str = "pose") -> Pose:
        obj = _require_object(value, where)
        return cls(
            _number(obj, "x", where), _number(obj, "y", where), _number(obj, "yaw_deg", where)
        )


@dataclass(frozen=True)
class Goal:
    goal_id: str
    pose: Pose


@dataclass(frozen=True)
class Status:
    """The ``status`` result, also the ``state`` telemetry payload."""

    state: BaseState
    goal_id: str | None
    pose: Pose
    battery_pct: float
    error: str | None

    def to_json(self) -> dict[str, Any]:
        return {
            "state": self.state.value,
            "goal_id": self.goal_id,
            "pose": self.pose.to_json(),
            "battery_pct": self.battery_pct,
            "error": self.error,
        }

    @classmethod
    def from_json(cls, value: Any) -> Status:
        obj = _require_object(value, "status")
        try:
            state = BaseState(obj.get("state", ""))
        except ValueError:
            raise _bad(f"status: unknown state {obj.get('state')!r}") from None
        return cls(
            state=state,
            goal_id=_optional_str(obj, "goal_id", "status"),
            pose=Pose.from_json(obj.get("pose"), "status.pose"),
            battery_pct=_number(obj, "battery_pct", "status"),
            error=_optional_str(obj, "error", "status"),
        )


@dataclass(frozen=True)
class Request:
    id: str
    cmd: Command
    args: dict[str, Any] = field(default_factory=dict)
    session: str | None = None
    """The base's ``session`` from ``hello``; ``None`` for older clients."""


@dataclass(frozen=True)
class Reply:
    id: str | None
    ok: bool
    result: dict[str, Any] | None = None
    error_code: ErrorCode | None = None
    error_message: str | None = None

    @classmethod
    def success(cls, request_id: str, result: dict[str, Any]) -> Reply:
        return cls(request_id, True, result=result)

    @classmethod
    def failure(cls, request_id: str | None, code: ErrorCode, message: str) -> Reply:
        return cls(request_id, False, error_code=code, error_message=message)


def _bad(message: str, request_id: str | None = None) -> ProtocolError:
    return ProtocolError(ErrorCode.BAD_REQUEST, message, request_id)


def _require_object(value: Any, where: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise _bad(f"{where} must be a JSON object")
    return value


def _number(obj: dict[str, Any], key: str, where: str) -> float:
    value = obj.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _bad(f"{where}.{key} must be a number, got {type(value).__name__}")
    if isinstance(value, int) and abs(value) > MAX_ABS_COORDINATE:
        raise _bad(f"{where}.{key} is out of range")
    number = float(value)
    if not math.isfinite(number) or abs(number) > MAX_ABS_COORDINATE:
        raise _bad(f"{where}.{key} must be finite and at most {MAX_ABS_COORDINATE:g} in size")
    return number


def _optional_str(obj: dict[str, Any], key: str, where: str) -> str | None:
    value = obj.get(key)
    if value is not None and not isinstance(value, str):
        raise _bad(f"{where}.{key} must be a string or null")
    return value


def _non_finite(name: str) -> float:
    """NaN and Infinity parse as floats so that validation can name the field and keep the id."""
    return float(name)


def _loads(data: bytes) -> Any:
    if len(data) > MAX_MESSAGE_BYTES:
        raise _bad(f"message of {len(data)} bytes exceeds {MAX_MESSAGE_BYTES}")
    try:
        return json.loads(data.decode("utf-8"), parse_constant=_non_finite)
    except (UnicodeDecodeError, ValueError, RecursionError) as error:
        raise _bad(f"not valid JSON: {error}") from None


def dumps(obj: Any) -> bytes:
    """Compact UTF-8 JSON; NaN and infinities are refused (``ValueError``)."""
    return json.dumps(obj, allow_nan=False, separators=(",", ":")).encode("utf-8")


# --- requests -----------------------------------------------------------------


def encode_request(request: Request) -> bytes:
    obj: dict[str, Any] = {"v": PROTOCOL_VERSION, "id": request.id, "cmd": request.cmd.value}
    obj["args"] = request.args
    if request.session is not None:
        obj["session"] = request.session
    return dumps(obj)


def decode_request(data: bytes) -> Request:
    """Parse and validate one request frame; raises :class:`ProtocolError`."""
    obj = _require_object(_loads(data), "request")
    request_id = obj.get("id")
    if not isinstance(request_id, str) or not 0 < len(request_id) <= MAX_ID_CHARS:
        raise _bad(f"id must be a string of 1 to {MAX_ID_CHARS} characters")
    if "v" not in obj:
        raise _bad("v (protocol version) is missing", request_id)
    if obj["v"] != PROTOCOL_VERSION or isinstance(obj["v"], bool):
        raise ProtocolError(
            ErrorCode.VERSION, f"protocol version {obj['v']!r} unsupported, expected 1", request_id
        )
    if "cmd" not in obj:
        raise _bad("cmd (the command's name, a string) is missing", request_id)
    if not isinstance(obj["cmd"], str):
        given = json.dumps(obj["cmd"])[:40]  # as the client wrote it: null, 3, [...]
        raise _bad(f"cmd must be the command's name, a string, not {given}", request_id)
    try:
        cmd = Command(obj["cmd"])
    except ValueError:
        raise ProtocolError(
            ErrorCode.UNKNOWN_COMMAND, f"unknown command {obj.get('cmd')!r}", request_id
        ) from None
    args = obj.get("args", {})
    if not isinstance(args, dict):
        raise _bad("args must be a JSON object", request_id)
    try:
        _validate_args(cmd, args)
    except ProtocolError as error:
        raise _bad(error.message, request_id) from None
    session = obj.get("session")
    if session is not None and (
        not isinstance(session, str) or not 0 < len(session) <= MAX_SESSION_CHARS
    ):
        raise _bad(f"session must be a string of 1 to {MAX_SESSION_CHARS} characters", request_id)
    return Request(request_id, cmd, args, session)


_ALLOWED_ARGS: dict[Command, frozenset[str]] = {
    Command.HELLO: frozenset({"client"}),
    Command.GOTO: frozenset({"goal_id", "x", "y", "yaw_deg"}),
    Command.CANCEL: frozenset({"goal_id"}),
}


def _validate_args(cmd: Command, args: dict[str, Any]) -> None:
    unexpected = set(args) - _ALLOWED_ARGS.get(cmd, frozenset())
    if unexpected:
        raise _bad(f"{cmd.value}: unexpected argument(s) {sorted(unexpected)}")
    if cmd is Command.HELLO and not isinstance(args.get("client", ""), str):
        raise _bad("hello: client must be a string")
    if cmd in (Command.GOTO, Command.CANCEL):
        goal_id = args.get("goal_id")
        if not isinstance(goal_id, str) or not 0 < len(goal_id) <= MAX_ID_CHARS:
            raise _bad(f"{cmd.value}: goal_id must be a string of 1 to {MAX_ID_CHARS} characters")
    if cmd is Command.GOTO:
        for key in ("x", "y", "yaw_deg"):
            _number(args, key, "goto")


def goal_from_args(args: dict[str, Any]) -> Goal:
    """The goal of a validated ``goto`` request."""
    return Goal(args["goal_id"], Pose(float(args["x"]), float(args["y"]), float(args["yaw_deg"])))


# --- replies --------------------------------------------------------------------


def encode_reply(reply: Reply) -> bytes:
    obj: dict[str, Any] = {"v": PROTOCOL_VERSION, "id": reply.id, "ok": reply.ok}
    if reply.ok:
        obj["result"] = reply.result if reply.result is not None else {}
    else:
        code = reply.error_code or ErrorCode.BAD_REQUEST
        obj["error"] = {"code": code.value, "message": reply.error_message or ""}
    return dumps(obj)


def decode_reply(data: bytes) -> Reply:
    """Parse one reply frame (client side); raises :class:`ProtocolError` when malformed."""
    obj = _require_object(_loads(data), "reply")
    reply_id = obj.get("id")
    if reply_id is not None and not isinstance(reply_id, str):
        raise _bad("reply id must be a string or null")
    if obj.get("v") != PROTOCOL_VERSION:
        raise ProtocolError(ErrorCode.VERSION, f"reply has protocol version {obj.get('v')!r}")
    if obj.get("ok") is True:
        return Reply(reply_id, True, result=_require_object(obj.get("result", {}), "result"))
    error = _require_object(obj.get("error"), "reply.error")
    try:
        code = ErrorCode(error.get("code", ""))
    except ValueError:
        raise _bad(f"reply has unknown error code {error.get('code')!r}") from None
    return Reply(reply_id, False, error_code=code, error_message=str(error.get("message", "")))


# --- telemetry ------------------------------------------------------------------


def encode_pose_telemetry(t_s: float, pose: Pose) -> list[bytes]:
    """The two frames of a ``pose`` message; ``t_s`` is the base's clock in seconds."""
    return [TOPIC_POSE, dumps({"t": t_s, **pose.to_json()})]


def encode_state_telemetry(status: Status) -> list[bytes]:
    return [TOPIC_STATE, dumps(status.to_json())]


def decode_telemetry(frames: list[bytes]) -> tuple[float, Pose] | Status:
    """A ``pose`` message as ``(t_s, pose)`` or a ``state`` message as :class:`Status`."""
    if len(frames) != 2:
        raise _bad(f"telemetry must have 2 frames, got {len(frames)}")
    topic, payload = frames
    obj = _loads(payload)
    if topic == TOPIC_POSE:
        pose_obj = _require_object(obj, "pose")
        return _number(pose_obj, "t", "pose"), Pose.from_json(pose_obj)
    if topic == TOPIC_STATE:
        return Status.from_json(obj)
    raise _bad(f"unknown telemetry topic {topic[:32]!r}")
