"""Byte-level tests of fieldapp-base/1 encoding, decoding and validation."""

from __future__ import annotations

import json

import pytest

from devices.base.protocol import (
    MAX_MESSAGE_BYTES,
    BaseState,
    Command,
    ErrorCode,
    Pose,
    ProtocolError,
    Reply,
    Request,
    Status,
    decode_reply,
    decode_request,
    decode_telemetry,
    encode_pose_telemetry,
    encode_reply,
    encode_request,
    encode_state_telemetry,
    goal_from_args,
)


def _request_bytes(**fields: object) -> bytes:
    obj: dict[str, object] = {"v": 1, "id": "s-000001", "cmd": "heartbeat", "args": {}}
    obj.update(fields)
    return json.dumps(obj).encode()


def _goto(**args: object) -> bytes:
    full: dict[str, object] = {"goal_id": "s05", "x": 1.6, "y": 1.6, "yaw_deg": 0.0}
    full.update(args)
    return _request_bytes(cmd="goto", args=full)


def test_spec_example_goto_decodes_to_its_goal() -> None:
    raw = b'{"v": 1, "id": "c1f6-000042", "cmd": "goto", "args": {"goal_id": "s05", "x": 1.6, "y": 1.6, "yaw_deg": 0.0}}'  # noqa: E501
    request = decode_request(raw)
    assert request.id == "c1f6-000042"
    assert request.cmd is Command.GOTO
    goal = goal_from_args(request.args)
    assert goal.goal_id == "s05"
    assert goal.pose == Pose(1.6, 1.6, 0.0)


def test_request_round_trip() -> None:
    request = Request("abc-000007", Command.CANCEL, {"goal_id": "g"})
    assert decode_request(encode_request(request)) == request


@pytest.mark.parametrize(
    ("raw", "code", "request_id"),
    [
        (b"not json", ErrorCode.BAD_REQUEST, None),
        (b"\xff\xfe", ErrorCode.BAD_REQUEST, None),
        (b"[1, 2]", ErrorCode.BAD_REQUEST, None),
        (b'{"v": 1, "cmd": "status"}', ErrorCode.BAD_REQUEST, None),
        (b'{"v": 1, "id": 5, "cmd": "status"}', ErrorCode.BAD_REQUEST, None),
        (b'{"v": 1, "id": "", "cmd": "status"}', ErrorCode.BAD_REQUEST, None),
        (b'{"id": "a", "cmd": "status"}', ErrorCode.BAD_REQUEST, "a"),
        (b'{"v": 2, "id": "a", "cmd": "status"}', ErrorCode.VERSION, "a"),
        (b'{"v": true, "id": "a", "cmd": "status"}', ErrorCode.VERSION, "a"),
        (b'{"v": 1, "id": "a", "cmd": "fly"}', ErrorCode.UNKNOWN_COMMAND, "a"),
        (b'{"v": 1, "id": "a"}', ErrorCode.BAD_REQUEST, "a"),  # no command: malformed
        (b'{"v": 1, "id": "a", "cmd": 3}', ErrorCode.BAD_REQUEST, "a"),
        (b'{"v": 1, "id": "a", "cmd": null}', ErrorCode.BAD_REQUEST, "a"),
        (b'{"v": 1, "id": "a", "cmd": "status", "args": [1]}', ErrorCode.BAD_REQUEST, "a"),
        (b'{"v": 1, "id": "a", "cmd": "stop", "args": {"now": 1}}', ErrorCode.BAD_REQUEST, "a"),
    ],
)
def test_malformed_requests_get_their_code(
    raw: bytes, code: ErrorCode, request_id: str | None
) -> None:
    with pytest.raises(ProtocolError) as caught:
        decode_request(raw)
    assert caught.value.code is code
    assert caught.value.request_id == request_id


@pytest.mark.parametrize(
    "raw",
    [
        _goto(x=float("nan")),
        _goto(x=float("inf")),
        _goto(y=float("-inf")),
        _goto(x=1e308),
        _goto(x=10**30),
        _goto(yaw_deg=True),
        _goto(x="1.0"),
        _goto(x=None),
        _goto(goal_id=""),
        _goto(goal_id=7),
        _goto(goal_id="g" * 129),
        _request_bytes(cmd="goto", args={"goal_id": "g", "x": 1.0, "y": 1.0}),
        _request_bytes(cmd="cancel", args={}),
        _request_bytes(cmd="hello", args={"client": 3}),
    ],
)
def test_bad_arguments_are_bad_requests_with_the_id(raw: bytes) -> None:
    with pytest.raises(ProtocolError) as caught:
        decode_request(raw)
    assert caught.value.code is ErrorCode.BAD_REQUEST
    assert caught.value.request_id == "s-000001"


def test_overflowing_literals_are_bad_requests() -> None:
    for literal in (b"1e400", b"-1e999", b"9" * 5000):
        raw = _goto().replace(b'"x": 1.6', b'"x": ' + literal)
        with pytest.raises(ProtocolError) as caught:
            decode_request(raw)
        assert caught.value.code is ErrorCode.BAD_REQUEST


def test_frames_over_the_size_limit_are_refused_before_parsing() -> None:
    raw = _request_bytes(args={"pad": "x" * MAX_MESSAGE_BYTES})
    with pytest.raises(ProtocolError, match="exceeds 65536"):
        decode_request(raw)


def test_deep_nesting_is_a_bad_request_not_a_crash() -> None:
    raw = b'{"v": 1, "id": "a", "cmd": "status", "args": ' + b"[" * 50000 + b"]" * 50000 + b"}"
    with pytest.raises(ProtocolError):
        decode_request(raw[:MAX_MESSAGE_BYTES])


def test_replies_round_trip_and_refuse_non_finite_results() -> None:
    ok = Reply.success("a-1", {"accepted": True})
    assert decode_reply(encode_reply(ok)) == ok
    failure = Reply.failure("a-2", ErrorCode.OUT_OF_BOUNDS, "x=12.0 outside the map")
    assert decode_reply(encode_reply(failure)) == failure
    anonymous = Reply.failure(None, ErrorCode.BAD_REQUEST, "not JSON")
    assert json.loads(encode_reply(anonymous))["id"] is None
    with pytest.raises(ValueError, match="JSON compliant"):
        encode_reply(Reply.success("a-3", {"x": float("nan")}))


def test_reply_wire_format_matches_the_spec() -> None:
    wire = json.loads(encode_reply(Reply.failure("c-43", ErrorCode.OUT_OF_BOUNDS, "off")))
    assert wire == {
        "v": 1,
        "id": "c-43",
        "ok": False,
        "error": {"code": "out_of_bounds", "message": "off"},
    }


def test_telemetry_round_trip() -> None:
    pose = Pose(1.0, -2.5, 45.0)
    frames = encode_pose_telemetry(12.5, pose)
    assert frames[0] == b"pose"
    assert json.loads(frames[1]) == {"t": 12.5, "x": 1.0, "y": -2.5, "yaw_deg": 45.0}
    assert decode_telemetry(frames) == (12.5, pose)
    status = Status(BaseState.STOPPED, "g1", pose, 87.5, "link lost")
    frames = encode_state_telemetry(status)
    assert frames[0] == b"state"
    assert decode_telemetry(frames) == status
    with pytest.raises(ProtocolError):
        decode_telemetry([b"weather", b"{}"])


@pytest.mark.parametrize(
    ("raw", "said"),
    [
        (b'{"v": 1, "id": "a"}', "cmd (the command's name, a string) is missing"),
        (b'{"v": 1, "id": "a", "cmd": 3}', "cmd must be the command's name, a string, not 3"),
        (b'{"v": 1, "id": "a", "cmd": null}', "cmd must be the command's name, a string, not null"),
    ],
)
def test_a_command_missing_and_one_not_a_name_are_told_apart(raw: bytes, said: str) -> None:
    with pytest.raises(ProtocolError) as caught:
        decode_request(raw)
    assert caught.value.message == said
