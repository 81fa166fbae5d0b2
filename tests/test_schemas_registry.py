"""The registry: one-call dispatch of every kind, replies that echo their request, error replies with
325001/399002 and secret-free reasons, extension methods, and the result-code table."""

from __future__ import annotations

import ast
import json
import sys
from pathlib import Path
from typing import Any

import pytest
from pydantic import ValidationError

import schemas
from schemas import (
    EXTENSION_PREFIX,
    SEED_METHODS,
    InboundModel,
    OutboundModel,
    Profile,
    ResultCode,
    ResultReply,
    TopicKind,
    default_registry,
    echo_heart_beat,
    error_reply_from_validation,
    ground_station_ack,
    is_valid_result,
    meaning,
    property_set_reply,
    reply_for,
    result_for_validation_error,
)
from schemas.base import Float
from schemas.examples import SEED_003
from schemas.services import FlyToPoint

SEED_METHOD_NAMES = {
    TopicKind.SERVICES: {
        "flight_authority_grab",
        "payload_authority_grab",
        "drc_mode_enter",
        "drc_mode_exit",
        "takeoff_to_point",
        "fly_to_point",
        "fly_to_point_stop",
        "camera_mode_switch",
        "camera_photo_take",
        "camera_recording_start",
        "camera_recording_stop",
        "camera_screen_drag",
        "camera_aim",
        "camera_focal_length_set",
        "gimbal_reset",
    },
    TopicKind.EVENTS: {
        "fly_to_point_progress",
        "takeoff_to_point_progress",
        "drc_status_notify",
        "joystick_invalid_notify",
    },
    TopicKind.DRC_DOWN: {"drone_control", "drone_emergency_stop", "heart_beat"},
    TopicKind.DRC_UP: {
        "drone_control",
        "drone_emergency_stop",
        "heart_beat",
        "hsi_info_push",
        "delay_info_push",
        "osd_info_push",
    },
    TopicKind.STATUS: {"update_topo"},
}

#: Newer DRC methods from DJI's Cloud API docs (Dock 2/3, RC Plus 2), beyond seed 003 (docs/cloud-api.md).
DJI_DOC_METHOD_NAMES: dict[TopicKind, set[str]] = {
    # cloud-control authorisation (RC Plus 2 / RC Pro "DRC" page: docs/cloud-api.md)
    # and live streaming (DJI's live page: docs/video.md)
    TopicKind.SERVICES: {
        "cloud_control_auth_request",
        "cloud_control_release",
        "live_start_push",
        "live_stop_push",
        "live_set_quality",
        "live_lens_change",
    },
    TopicKind.EVENTS: {"cloud_control_auth_notify"},
    TopicKind.DRC_DOWN: {"stick_control", "drc_gimbal_reset"},
    TopicKind.DRC_UP: {
        "stick_control",
        "drc_gimbal_reset",
        "drc_drone_state_push",
        "drc_batteries_info_push",
    },
}


def _seed(kind: TopicKind, method: str) -> dict[str, Any]:
    (example,) = [e for e in SEED_003 if e.kind is kind and e.method == method]
    return {**json.loads(example.text), **example.patch}


#: The wayline methods of a dock-like gateway (schemas/wayline.py), beside seed 003's.
WAYLINE_METHOD_NAMES: dict[TopicKind, set[str]] = {
    TopicKind.SERVICES: {
        "flighttask_prepare",
        "flighttask_execute",
        "flighttask_undo",
        "flighttask_pause",
        "flighttask_recovery",
        "return_home",
        "return_home_cancel",
    },
    TopicKind.EVENTS: {"flighttask_progress", "flighttask_ready", "return_home_info"},
    TopicKind.REQUESTS: {"flighttask_resource_get"},
}


def test_registry_holds_every_seed_method() -> None:
    registry = default_registry()
    for kind, names in SEED_METHOD_NAMES.items():
        extra = DJI_DOC_METHOD_NAMES.get(kind, set()) | WAYLINE_METHOD_NAMES.get(kind, set())
        assert set(registry.methods(kind)) == names | extra
    for kind in (TopicKind.DRC_DOWN, TopicKind.SERVICES, TopicKind.EVENTS):
        for method in DJI_DOC_METHOD_NAMES[kind]:
            assert registry.spec(kind, method).source.startswith("DJI Cloud API docs § "), method
    services, events = (
        SEED_METHOD_NAMES[k] | WAYLINE_METHOD_NAMES[k] | DJI_DOC_METHOD_NAMES[k]
        for k in (TopicKind.SERVICES, TopicKind.EVENTS)
    )
    assert set(registry.methods(TopicKind.SERVICES_REPLY)) == services
    assert set(registry.methods(TopicKind.EVENTS_REPLY)) == events
    assert set(registry.methods(TopicKind.REQUESTS)) == {"flighttask_resource_get"}
    assert set(registry.methods(TopicKind.REQUESTS_REPLY)) == {"flighttask_resource_get"}
    assert all(spec.source for spec in SEED_METHODS)


def test_validate_returns_the_typed_message_in_one_call() -> None:
    registry = default_registry()
    raw = json.dumps(_seed(TopicKind.SERVICES, "fly_to_point")).encode()
    message = registry.validate(TopicKind.SERVICES, raw)
    assert type(message) is registry.message_class(TopicKind.SERVICES, "fly_to_point")
    assert isinstance(message.data, FlyToPoint)
    assert registry.spec(TopicKind.SERVICES, "fly_to_point").data is FlyToPoint


def test_reply_for_echoes_tid_bid_method() -> None:
    registry = default_registry()
    request = registry.validate(
        TopicKind.SERVICES, {**_seed(TopicKind.SERVICES, "gimbal_reset"), "tid": "T1"}
    )
    reply = reply_for(
        request, ResultCode.GIMBAL_AT_LIMIT, {"reason": "pitch at limit"}, timestamp=42, gateway="GW"
    )
    assert json.loads(reply.model_dump_json()) == {
        "tid": "T1",
        "bid": request.bid,
        "timestamp": 42,
        "gateway": "GW",
        "method": "gimbal_reset",
        "data": {"result": 327014, "output": {"reason": "pitch at limit"}},
    }
    assert type(reply) is registry.message_class(TopicKind.SERVICES_REPLY, "gimbal_reset")
    with pytest.raises(ValueError, match="timestamp"):
        reply_for(request, 0)
    with pytest.raises(ValidationError):  # the six-digit rule holds for replies too
        reply_for(request, -1, timestamp=1)
    with pytest.raises(ValidationError):  # an output the contract does not define
        reply_for(request, 0, {"secret": 1}, timestamp=1)


def test_drc_replies_have_no_tid_bid_and_echo_heartbeats() -> None:
    registry = default_registry()
    control = registry.validate(TopicKind.DRC_DOWN, {"method": "drone_control", "data": {"seq": 4}})
    reply = reply_for(control, ResultCode.DRC_SEQ_TOO_OLD, {"seq": 4})
    assert json.loads(reply.model_dump_json()) == {
        "method": "drone_control",
        "data": {"result": 319033, "output": {"seq": 4}},
    }
    beat = registry.validate(TopicKind.DRC_DOWN, {"method": "heart_beat", "seq": 3, "data": {"ts": 99}})
    assert json.loads(echo_heart_beat(beat).model_dump_json()) == {  # seq where it came, and in data
        "method": "heart_beat",
        "seq": 3,
        "data": {"seq": 3, "timestamp": 99},
    }
    with pytest.raises(ValueError, match="not answered with a result"):
        reply_for(beat, 0)


def test_events_are_built_and_their_answers_parsed() -> None:
    registry = default_registry()
    event = registry.build(
        TopicKind.EVENTS,
        "drc_status_notify",
        {"result": 514301, "drc_state": 0},
        tid="t",
        bid="b",
        timestamp=1,
        gateway="GW",
        need_reply=1,
    )
    assert json.loads(event.model_dump_json())["data"] == {"result": 514301, "drc_state": 0}
    with pytest.raises(ValidationError):
        registry.build(TopicKind.EVENTS, "drc_status_notify", {"result": 0, "drc_state": 2}, tid="t", bid="b")
    with pytest.raises(ValidationError):  # need_reply is 0/1, not a boolean
        registry.build(
            TopicKind.EVENTS,
            "drc_status_notify",
            {"result": 0, "drc_state": 2},
            tid="t",
            bid="b",
            timestamp=1,
            need_reply=True,
        )
    answer = registry.validate(
        TopicKind.EVENTS_REPLY,
        b'{"tid":"t","bid":"b","method":"drc_status_notify",'
        b'"data":{"result":0,"output":{"any":[1]}},"newer":true}',
    )
    assert answer.data.result == 0
    with pytest.raises(ValueError, match="not a request from the cloud"):
        reply_for(event, 0, timestamp=1)


def test_telemetry_needs_a_profile() -> None:
    registry = default_registry()
    raw = {"tid": "t", "bid": "b", "timestamp": 1, "gateway": "GW", "data": {"drc_state": 1}}
    assert registry.validate(TopicKind.OSD, raw, profile=Profile.GATEWAY).data.drc_state == 1
    with pytest.raises(ValueError, match="profile"):
        registry.validate(TopicKind.OSD, raw)
    with pytest.raises(ValidationError):  # osd needs the gateway field
        registry.validate(TopicKind.OSD, {**raw, "gateway": None}, profile="gateway")
    with pytest.raises(ValidationError):  # a body must say something
        registry.validate(TopicKind.OSD, {**raw, "data": {}}, profile="aircraft")


def test_aircraft_osd_payload_keys() -> None:
    registry = default_registry()
    body = {"latitude": 1.0, "39-0-7": {"payload_index": "39-0-7", "gimbal_pitch": -90}}
    raw = {"tid": "t", "bid": "b", "timestamp": 1, "gateway": "GW", "data": body}
    message = registry.validate(TopicKind.OSD, raw, profile="aircraft")
    assert json.loads(message.model_dump_json())["data"]["39-0-7"]["gimbal_pitch"] == -90
    for bad in ({"39-0-8": body["39-0-7"]}, {"pitch": 1}, {"39-0-7": {"payload_index": "39-0-7", "x": 1}}):
        with pytest.raises(ValidationError):
            registry.validate(TopicKind.OSD, {**raw, "data": {"latitude": 1.0, **bad}}, profile="aircraft")


# ------------------------------------------------------------------------------------- error replies


def test_bad_parameters_give_325001_with_a_short_reason() -> None:
    registry = default_registry()
    raw = _seed(TopicKind.SERVICES, "fly_to_point")
    raw["data"]["points"][0]["height"] = 10001
    payload = json.dumps(raw).encode()
    with pytest.raises(ValidationError) as caught:
        registry.validate(TopicKind.SERVICES, payload)
    assert result_for_validation_error(caught.value) is ResultCode.INVALID_PARAMETERS
    reply = error_reply_from_validation(TopicKind.SERVICES, payload, caught.value, timestamp=5, gateway="GW")
    assert reply is not None
    dumped = json.loads(reply.model_dump_json())
    assert dumped["tid"] == raw["tid"] and dumped["bid"] == raw["bid"] and dumped["method"] == "fly_to_point"
    assert dumped["data"]["result"] == 325001
    assert (
        dumped["data"]["output"]["reason"]
        == "data.points.0.height: Input should be less than or equal to 10000"
    )


def test_unknown_method_gives_399002() -> None:
    registry = default_registry()
    raw = {"tid": "t", "bid": "b", "timestamp": 1, "method": "launch_rockets", "data": {}}
    with pytest.raises(ValidationError) as caught:
        registry.validate(TopicKind.SERVICES, raw)
    reply = error_reply_from_validation(TopicKind.SERVICES, raw, caught.value, timestamp=5)
    assert reply is not None and reply.data.result == ResultCode.UNKNOWN_METHOD
    assert reply.method == "launch_rockets"
    # a kind with no method at all behaves the same
    with pytest.raises(ValidationError) as caught:
        registry.validate(TopicKind.REQUESTS_REPLY, raw)
    assert result_for_validation_error(caught.value) is ResultCode.UNKNOWN_METHOD


def test_reasons_never_leak_credentials_or_values() -> None:
    registry = default_registry()
    raw = _seed(TopicKind.SERVICES, "drc_mode_enter")
    raw["data"]["mqtt_broker"]["password"] = 123456789  # wrong type: pydantic would quote it
    raw["data"]["mqtt_broker"]["address"] = "secret-host.example:99999"
    raw["data"]["osd_frequency"] = 99
    with pytest.raises(ValidationError) as caught:
        registry.validate(TopicKind.SERVICES, raw)
    reply = error_reply_from_validation(TopicKind.SERVICES, raw, caught.value, timestamp=5)
    assert reply is not None
    text = reply.model_dump_json()
    assert "123456789" not in text and "secret-host" not in text and "sn_a" not in text
    assert "data.mqtt_broker.password: invalid value" in text
    assert reply.data.result == 325001
    assert len(reply.data.output.reason) <= 300


def test_string_inputs_are_not_quoted() -> None:
    registry = default_registry()
    raw = _seed(TopicKind.SERVICES, "camera_aim")
    raw["data"]["camera_type"] = "laser-pointer-of-doom"
    with pytest.raises(ValidationError) as caught:
        registry.validate(TopicKind.SERVICES, raw)
    reply = error_reply_from_validation(TopicKind.SERVICES, raw, caught.value, timestamp=5)
    assert reply is not None and "laser" not in reply.model_dump_json()


@pytest.mark.parametrize(
    ("kind", "payload", "answered"),
    [
        (TopicKind.SERVICES, b"not json", False),  # no tid to echo
        (TopicKind.SERVICES, b'{"tid": "t", "bid": "b"}', False),  # no method to echo
        (TopicKind.SERVICES, b'{"tid": "t", "bid": "b", "method": "camera_aim"}', True),
        (TopicKind.SERVICES, b'{"tid": 1, "bid": "b", "method": "camera_aim"}', False),
        (TopicKind.DRC_DOWN, b'{"method": "drone_control", "data": {"seq": -1}}', True),
        (TopicKind.DRC_DOWN, b'{"data": {"seq": 1}}', False),
        (
            TopicKind.EVENTS_REPLY,
            b'{"tid": "t", "bid": "b", "method": "x", "data": 5}',
            False,
        ),  # never answered
        (
            TopicKind.PROPERTY_SET,
            b'{"tid": "t", "bid": "b", "data": {"rth_altitude": 1, "BAD KEY": 2}}',
            True,
        ),
    ],
)
def test_when_a_reply_is_possible(kind: TopicKind, payload: bytes, answered: bool) -> None:
    registry = default_registry()
    with pytest.raises(ValidationError) as caught:
        registry.validate(kind, payload)
    reply = error_reply_from_validation(kind, payload, caught.value, timestamp=1)
    assert (reply is not None) == answered
    if reply is not None:
        json.loads(reply.model_dump_json())


def test_property_set_round_trip() -> None:
    registry = default_registry()
    request = registry.validate(TopicKind.PROPERTY_SET, b'{"tid":"t","bid":"b","data":{"rth_altitude":120}}')
    reply = property_set_reply(request, {"rth_altitude": ResultCode.METHOD_NOT_SUPPORTED}, timestamp=3)
    assert json.loads(reply.model_dump_json()) == {
        "tid": "t",
        "bid": "b",
        "timestamp": 3,
        "data": {"rth_altitude": {"result": 399001}},
    }
    with pytest.raises(ValidationError):
        registry.validate(TopicKind.PROPERTY_SET, b'{"tid":"t","bid":"b","data":{}}')


# ------------------------------------------------------------------------------------- extensions


class GimbalSpeed(InboundModel):
    """x_rsdk_gimbal_speed: a test extension."""

    yaw: Float


def test_adapters_register_extension_methods() -> None:
    registry = default_registry()
    spec = registry.register(
        TopicKind.SERVICES, "x_rsdk_gimbal_speed", GimbalSpeed, ResultReply, summary="speed"
    )
    assert spec.method.startswith(EXTENSION_PREFIX) and spec.source == "extension"
    raw = {"tid": "t", "bid": "b", "method": "x_rsdk_gimbal_speed", "data": {"yaw": 10}}
    message = registry.validate(TopicKind.SERVICES, raw)
    assert message.data == GimbalSpeed(yaw=10)
    assert reply_for(message, 0, timestamp=1).method == "x_rsdk_gimbal_speed"
    # another registry is not affected
    with pytest.raises(ValidationError):
        default_registry().validate(TopicKind.SERVICES, raw)
    copy = registry.copy()
    assert copy.validate(TopicKind.SERVICES, raw).data == GimbalSpeed(yaw=10)


@pytest.mark.parametrize(
    ("kind", "method", "data", "reply", "why"),
    [
        (TopicKind.SERVICES, "gimbal_speed", GimbalSpeed, ResultReply, "must start with"),
        (TopicKind.SERVICES_REPLY, "x_a", GimbalSpeed, None, "registered on"),
        (TopicKind.SERVICES, "x_a", ResultReply, ResultReply, "InboundModel"),
        (TopicKind.SERVICES, "x_a", GimbalSpeed, GimbalSpeed, "OutboundModel"),
        (TopicKind.DRC_UP, "x_a", ResultReply, ResultReply, "no reply"),
        (TopicKind.SERVICES, "x_Bad Name", GimbalSpeed, ResultReply, "snake case"),
    ],
)
def test_register_refuses_bad_entries(kind: TopicKind, method: str, data: Any, reply: Any, why: str) -> None:
    with pytest.raises(ValueError, match=why):
        default_registry().register(kind, method, data, reply, summary="bad")


def test_register_refuses_clashes_unless_replacing() -> None:
    registry = default_registry()
    registry.register(TopicKind.SERVICES, "x_a", GimbalSpeed, ResultReply, summary="a")
    with pytest.raises(ValueError, match="already registered"):
        registry.register(TopicKind.SERVICES, "x_a", GimbalSpeed, ResultReply, summary="a")

    class Other(InboundModel):
        pitch: Float

    registry.register(TopicKind.SERVICES, "x_a", Other, ResultReply, summary="a", replace=True)
    assert registry.validate(
        TopicKind.SERVICES, {"tid": "t", "bid": "b", "method": "x_a", "data": {"pitch": 1}}
    )

    class Push(OutboundModel):
        value: Float

    registry.register(TopicKind.DRC_UP, "x_push", Push, summary="push")
    with pytest.raises(ValueError, match="already registered"):  # would collide with the reply on drc/up
        registry.register(TopicKind.DRC_DOWN, "x_push", GimbalSpeed, ResultReply, summary="clash")


# ------------------------------------------------------------------------------------- result codes


def test_result_codes_follow_the_rule_and_have_meanings() -> None:
    for code in ResultCode:
        assert is_valid_result(int(code)), code
        assert code.meaning and meaning(int(code)) == code.meaning
    assert len({int(code) for code in ResultCode}) == len(ResultCode)
    assert ResultCode.INVALID_PARAMETERS == 325001 and ResultCode.BUSY == 314000
    assert [int(c) for c in ResultCode if 327004 <= c <= 327010] == list(range(327004, 327011))
    assert [int(c) for c in ResultCode if 514300 <= c <= 514304] == list(range(514300, 514305))
    assert not is_valid_result(True) and not is_valid_result(1) and not is_valid_result(425001)


def test_ground_station_ack_family() -> None:
    assert ground_station_ack(0) == 0
    assert ground_station_ack(4) == 336004 and is_valid_result(336004)
    assert "ACK 4" in meaning(336004)
    with pytest.raises(ValueError):
        ground_station_ack(1000)


def test_odd_inbound_gateway_is_accepted_but_not_echoed() -> None:
    registry = default_registry()
    raw = {**_seed(TopicKind.SERVICES, "camera_photo_take"), "gateway": "not a serial/number"}
    request = registry.validate(TopicKind.SERVICES, raw)
    assert reply_for(request, 0, timestamp=1).gateway is None
    assert reply_for(request, 0, timestamp=1, gateway="GW").gateway == "GW"


def test_schemas_imports_only_pydantic_and_the_standard_library() -> None:
    # schemas/ is the contract: it must not know adapters/ or gateway/ (DESIGN: dependencies point one way).
    allowed = set(sys.stdlib_module_names) | {"pydantic", "pydantic_core"}
    for path in sorted(Path(schemas.__file__).parent.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                root = name.split(".")[0]
                ok = root in allowed or (root == "yaml" and path.name == "export.py")
                assert ok, f"{path.name} imports {name}"
