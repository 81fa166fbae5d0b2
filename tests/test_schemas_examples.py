"""Every JSON example of seed 003 validates against its model and round-trips; each seed contradiction is
pinned to the decision documented on its model (schemas/examples.py holds the examples, verbatim)."""

from __future__ import annotations

import json
from typing import Any

import pytest
from pydantic import ValidationError

from schemas import Profile, ResultCode, TopicKind, default_registry, echo_heart_beat
from schemas.drc import DroneControl, HeartBeat, HsiInfoPush
from schemas.examples import CLOUD_SHAPES, GATEWAY_EXAMPLES, SEED_003, CloudShape, SeedExample
from schemas.services import CameraFocalLengthSet, DrcModeEnter, FlyToPoint, TakeoffToPoint

REGISTRY = default_registry()


def _validate(example: SeedExample, raw: Any) -> Any:
    if example.kind is TopicKind.STATE:
        return REGISTRY.validate(example.kind, raw, profile=Profile.AIRCRAFT)
    return REGISTRY.validate(example.kind, raw)


def _expected(example: SeedExample) -> dict[str, Any]:
    expected = {**json.loads(example.text), **example.patch}
    data = dict(expected.get("data") or {})
    for old, new in example.renames.items():
        data[new] = data.pop(old)
    return {**expected, "data": data}


def test_every_seed_example_is_here() -> None:
    # 44 ```json blocks in seed 003: 1 state, 4 events, 15 services + 15 replies, 9 DRC.
    assert len(SEED_003) == 44
    kinds = [example.kind for example in SEED_003]
    assert kinds.count(TopicKind.SERVICES) == kinds.count(TopicKind.SERVICES_REPLY) == 15
    assert kinds.count(TopicKind.EVENTS) == 4
    assert kinds.count(TopicKind.DRC_DOWN) == 3 and kinds.count(TopicKind.DRC_UP) == 6


@pytest.mark.parametrize("example", SEED_003, ids=lambda e: f"{e.kind.slug}.{e.method or 'state'}")
def test_seed_example_validates_and_round_trips(example: SeedExample) -> None:
    text = example.text
    if example.patch:  # the seed's example omits a key the contract requires (see example.note)
        text = json.dumps({**json.loads(text), **example.patch})
    message = _validate(example, text.encode())
    assert getattr(message, "method", None) == example.method
    dumped = json.loads(message.model_dump_json(context={"reveal_secrets": True}))
    assert dumped == _expected(example)
    # and once more through the model: the dump is a fixed point
    again = _validate(example, dumped)
    assert again == message


def test_gateway_examples_validate_and_round_trip() -> None:
    for example in GATEWAY_EXAMPLES:
        profile = example.name if example.kind in (TopicKind.OSD, TopicKind.STATE) else None
        message = REGISTRY.validate(example.kind, json.dumps(example.payload), profile=profile)
        assert json.loads(message.model_dump_json()) == example.payload


@pytest.mark.parametrize("shape", CLOUD_SHAPES, ids=lambda s: f"{s.method}:{s.source[:30]}")
def test_every_real_cloud_shape_is_read(shape: CloudShape) -> None:
    """Issue #17: what real clouds send (schemas.examples.CLOUD_SHAPES, each with its source) is read, as the
    tolerant reader documents: "data": "" or null is no parameters, 60.0 for an integer field is 60."""
    message = REGISTRY.validate(shape.kind, shape.text.encode())
    assert message.method == shape.method and shape.source
    assert json.loads(message.data.model_dump_json(context={"reveal_secrets": True})) == shape.reads


def test_the_tolerant_reader_takes_integral_floats_only() -> None:
    data = _seed(TopicKind.SERVICES, "takeoff_to_point")["data"]
    read = TakeoffToPoint.model_validate({**data, "rth_altitude": 60.0, "max_speed": 10.0})
    assert (read.rth_altitude, read.max_speed) == (60, 10) and type(read.rth_altitude) is int
    for field, value in (("rth_altitude", 60.5), ("max_speed", 10.25), ("rc_lost_action", 1.0)):
        with pytest.raises(ValidationError):  # a fraction, or an enum (enums take their integers only)
            TakeoffToPoint.model_validate({**data, field: value})
    schema = TakeoffToPoint.model_json_schema()
    assert schema["x-tolerant-reader"]["integral_float_fields"] == ["rth_altitude", "max_speed"]


@pytest.mark.parametrize(
    ("field", "value", "ok"),
    [
        ("target_height", 10000, True),
        ("target_height", 10000.5, False),
        ("target_height", 1.9, False),
        ("security_takeoff_height", 20, True),
        ("security_takeoff_height", 19.9, False),
        ("security_takeoff_height", 1500.1, False),
        ("max_speed", 0, False),
        ("max_speed", 16, False),
        ("rth_altitude", 1500, True),
        ("rth_altitude", 1501, False),
        ("flight_id", "a-b-c", True),
        *(("flight_id", f"a{c}b", False) for c in '._<>:"/\\|?*'),
        ("commander_flight_height", 3000, True),
        ("commander_flight_height", 3001, False),
        ("rth_mode", 2, False),
        ("commander_flight_mode", 2, False),
        ("simulate_mission", {"is_enable": 2, "latitude": 1.0, "longitude": 1.0}, False),
    ],
)
def test_takeoff_ranges_are_the_java_sdks(field: str, value: Any, ok: bool) -> None:
    """DJI's Java Cloud SDK TakeoffToPointRequest: target 2..10000, security 20..1500, rth 2..1500, speed
    1..15, flight_id without . _ < > : " / \\ | ? *, commander height 2..3000."""
    data = _seed(TopicKind.SERVICES, "takeoff_to_point")["data"]
    if ok:
        TakeoffToPoint.model_validate({**data, field: value})
    else:
        with pytest.raises(ValidationError):
            TakeoffToPoint.model_validate({**data, field: value})


def test_drc_credentials_expiry_is_the_java_sdks_range() -> None:
    data = _seed(TopicKind.SERVICES, "drc_mode_enter")["data"]
    for expire, ok in ((1234567890, True), (9999999999, True), (0, False), (10**10, False)):
        value = {**data, "mqtt_broker": {**data["mqtt_broker"], "expire_time": expire}}
        if ok:
            DrcModeEnter.model_validate(value)
        else:
            with pytest.raises(ValidationError):
                DrcModeEnter.model_validate(value)


def _seed(kind: TopicKind, method: str) -> dict[str, Any]:
    (example,) = [e for e in SEED_003 if e.kind is kind and e.method == method]
    return {**json.loads(example.text), **example.patch}


# ----------------------------------------------------------------------------- fly_to_point: points


def test_fly_to_point_seed_sends_two_points_and_both_are_kept_in_order() -> None:
    # Decision (services.FlyToPoint): at least one point, flown in order; the seed's example has two.
    raw = _seed(TopicKind.SERVICES, "fly_to_point")
    raw["data"]["points"][1]["height"] = 200
    message = REGISTRY.validate(TopicKind.SERVICES, raw)
    assert [point.height for point in message.data.points] == [100, 200]


def test_fly_to_point_point_count_limits() -> None:
    # DJI's Java Cloud SDK: @Size(min = 1), no maximum (a device refuses more than it can fly)
    point = {"latitude": 1.0, "longitude": 2.0, "height": 50}
    with pytest.raises(ValidationError):
        FlyToPoint.model_validate({"fly_to_id": "a", "max_speed": 5, "points": []})
    FlyToPoint.model_validate({"fly_to_id": "a", "max_speed": 5, "points": [point] * 300})


# ----------------------------------------------------------------------------- hsi_info_push: names


def test_hsi_accepts_both_array_names_and_emits_the_table_name() -> None:
    base = {"up_distance": 1, "down_distance": 2, "up_enable": True, "up_work": True, "down_enable": False}
    base["down_work"] = False
    for name in ("around_distances", "around_distance"):
        push = HsiInfoPush.model_validate({**base, name: [1, 2, 3]})
        dumped = json.loads(push.model_dump_json())
        assert dumped["around_distances"] == [1, 2, 3] and "around_distance" not in dumped
    with pytest.raises(ValidationError):
        HsiInfoPush.model_validate({**base, "around_distances": [1] * 361})
    with pytest.raises(ValidationError):  # outbound: a flag the contract does not define
        HsiInfoPush.model_validate({**base, "around_distances": [], "diagonal_enable": True})


# ----------------------------------------------------------------------------- drone_control: h, axes


@pytest.mark.parametrize(("h", "ok"), [(-4, True), (5, True), (5.01, False), (-4.01, False), (-5, False)])
def test_drone_control_h_is_minus4_to_5(h: float, ok: bool) -> None:
    # The seed writes "min 5, max -4"; read as -4..5 m/s (drc.DroneControl).
    if ok:
        assert DroneControl.model_validate({"seq": 1, "h": h}).h == h
    else:
        with pytest.raises(ValidationError):
            DroneControl.model_validate({"seq": 1, "h": h})


def test_drone_control_absent_axes_are_zero_and_seq_may_sit_beside_data() -> None:
    message = REGISTRY.validate(
        TopicKind.DRC_DOWN, b'{"method": "drone_control", "seq": 7, "data": {"y": 1.5}}'
    )
    assert message.data == DroneControl(seq=7, x=0.0, y=1.5, h=0.0, w=0.0)
    # the newer envelope's top-level seq wins over one in data (envelope.BESIDE_WINS)
    message = REGISTRY.validate(TopicKind.DRC_DOWN, {"method": "drone_control", "seq": 9, "data": {"seq": 8}})
    assert message.data.seq == 9
    with pytest.raises(ValidationError):  # no seq anywhere
        REGISTRY.validate(TopicKind.DRC_DOWN, {"method": "drone_control", "data": {"x": 1}})


# ----------------------------------------------------------------------------- heart_beat: ts / seq


@pytest.mark.parametrize(
    "raw",
    [
        {"method": "heart_beat", "data": {"seq": 10, "timestamp": 1670415891013}},  # the seed
        {"method": "heart_beat", "data": {"seq": 10, "ts": 1670415891013}},
        {"method": "heart_beat", "seq": 10, "data": {"ts": 1670415891013}},
        {"method": "heart_beat", "seq": 10, "timestamp": 1670415891013, "data": {}},
        {"method": "heart_beat", "seq": 10, "timestamp": 1670415891013},
    ],
)
def test_heart_beat_spellings(raw: dict[str, Any]) -> None:
    message = REGISTRY.validate(TopicKind.DRC_DOWN, raw)
    assert message.data == HeartBeat(seq=10, timestamp=1670415891013)


def test_drone_control_takes_the_java_sdks_freq_and_delay_time_in_its_ranges() -> None:
    """DJI's Java Cloud SDK sends freq (2..10 Hz) and delay_time (100..1000 ms) beside the axes:
    declared with the SDK's ranges (accepted, not used), refused outside them, integral floats read."""
    stick = DroneControl.model_validate({"seq": 1, "y": 1.0, "freq": 10, "delay_time": 100.0})
    assert (stick.freq, stick.delay_time) == (10, 100)
    for bad in ({"freq": 11}, {"freq": 1}, {"delay_time": 99}, {"delay_time": 1001}, {"freq": 5.5}):
        with pytest.raises(ValidationError):
            DroneControl.model_validate({"seq": 1, **bad})


def test_heart_beat_inside_wins_and_seq_is_optional() -> None:
    raw = {"method": "heart_beat", "timestamp": 5, "data": {"ts": 6}}
    assert REGISTRY.validate(TopicKind.DRC_DOWN, raw).data == HeartBeat(seq=None, timestamp=6)
    with pytest.raises(ValidationError):
        REGISTRY.validate(TopicKind.DRC_DOWN, {"method": "heart_beat", "data": {"seq": 1}})


# ----------------------------------------------------------------------------- envelopes and policy


@pytest.mark.parametrize("data", ["{}", "null", None])
def test_no_parameter_services_accept_empty_null_or_missing_data(data: str | None) -> None:
    text = '{"tid": "t", "bid": "b", "timestamp": 1, "method": "drc_mode_exit"'
    text += f', "data": {data}}}' if data is not None else "}"
    assert REGISTRY.validate(TopicKind.SERVICES, text).method == "drc_mode_exit"


def test_inbound_ignores_unknown_fields_outbound_rejects_them() -> None:
    raw = _seed(TopicKind.SERVICES, "camera_aim")
    raw["new_cloud_field"] = 1
    raw["data"]["future_option"] = {"x": 1}
    message = REGISTRY.validate(TopicKind.SERVICES, raw)
    assert "future_option" not in message.data.model_dump() and "new_cloud_field" not in message.model_dump()
    event = _seed(TopicKind.EVENTS, "drc_status_notify")
    event["data"]["extra"] = 1
    with pytest.raises(ValidationError):
        REGISTRY.validate(TopicKind.EVENTS, event)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("max_speed", "12"),
        ("max_speed", 12.5),
        ("max_speed", True),
        ("target_height", "100"),
        ("target_height", float("nan")),
        ("target_height", float("inf")),
        ("rc_lost_action", "1"),
        ("rc_lost_action", True),
        ("rc_lost_action", 1.0),
        ("rc_lost_action", 3),
        ("target_latitude", 90.5),
    ],
)
def test_safety_numbers_are_strict(field: str, value: Any) -> None:
    data = _seed(TopicKind.SERVICES, "takeoff_to_point")["data"]
    TakeoffToPoint.model_validate(data)
    with pytest.raises(ValidationError):
        TakeoffToPoint.model_validate({**data, field: value})


def test_ir_zoom_is_limited_to_20() -> None:
    CameraFocalLengthSet.model_validate(
        {"payload_index": "39-0-7", "camera_type": "zoom", "zoom_factor": 200}
    )
    CameraFocalLengthSet.model_validate({"payload_index": "39-0-7", "camera_type": "ir", "zoom_factor": 20})
    with pytest.raises(ValidationError):
        CameraFocalLengthSet.model_validate(
            {"payload_index": "39-0-7", "camera_type": "ir", "zoom_factor": 20.5}
        )


def test_drc_password_is_masked_unless_revealed() -> None:
    data = _seed(TopicKind.SERVICES, "drc_mode_enter")["data"]
    enter = DrcModeEnter.model_validate(data)
    assert "jwt_token" not in repr(enter) and "jwt_token" not in enter.model_dump_json()
    assert "jwt_token" in enter.model_dump_json(context={"reveal_secrets": True})
    assert enter.mqtt_broker.password.get_secret_value() == "jwt_token"


@pytest.mark.parametrize("frequency", [0, -1, 10.5, "10", "50", True])
def test_drc_frequencies_are_positive_integers(frequency: Any) -> None:
    data = _seed(TopicKind.SERVICES, "drc_mode_enter")["data"]
    for field in ("osd_frequency", "hsi_frequency"):
        with pytest.raises(ValidationError):
            DrcModeEnter.model_validate({**data, field: frequency})


@pytest.mark.parametrize("frequency", [30, 31, 50, 1000])
def test_drc_frequencies_above_30_hz_are_read_as_asked(frequency: int) -> None:
    """Issue #33: more than the device can do is no malformed request: read as asked (the DRC controller
    pushes at 30 Hz and says so in the reply, tests/test_drc_interop.py); the schema: 30 is used at most."""
    data = _seed(TopicKind.SERVICES, "drc_mode_enter")["data"]
    read = DrcModeEnter.model_validate({**data, "osd_frequency": frequency, "hsi_frequency": frequency})
    assert (read.osd_frequency, read.hsi_frequency) == (frequency, frequency)
    schema = DrcModeEnter.model_json_schema()["properties"]["osd_frequency"]
    assert schema["minimum"] == 1 and schema["x-used-at-most"] == 30


@pytest.mark.parametrize(("text", "read"), [("true", True), ("false", False)])
def test_the_tolerant_reader_takes_true_and_false_strings_for_booleans(text: str, read: bool) -> None:
    """Issue #33: "enable_tls": "false" (github wudizhr/DJI_Cloud_API_demo) is read as false; only the exact
    strings, only inbound (what the gateway sends stays strict)."""
    data = _seed(TopicKind.SERVICES, "drc_mode_enter")["data"]
    broker = data["mqtt_broker"]
    assert (
        DrcModeEnter.model_validate(
            {**data, "mqtt_broker": {**broker, "enable_tls": text}}
        ).mqtt_broker.enable_tls
        is read
    )
    for wrong in ("True", "FALSE", "1", "0", "yes", "", 1, 0, None):
        with pytest.raises(ValidationError):
            DrcModeEnter.model_validate({**data, "mqtt_broker": {**broker, "enable_tls": wrong}})
    schema = DrcModeEnter.model_json_schema()["$defs"]["MqttBroker"]
    assert schema["x-tolerant-reader"]["boolean_string_fields"] == ["enable_tls"]


@pytest.mark.parametrize(
    "method", ["return_home", "flight_authority_grab", "drc_mode_exit", "fly_to_point_stop"]
)
def test_the_string_null_as_data_is_no_parameters(method: str) -> None:
    """Issue #33: "data": "null" (a JSON string; github wudizhr/DJI_Cloud_API_demo's return_home) is read like
    null, "" and {}: no parameters. Other strings are still refused."""
    envelope = {"tid": "t-1", "bid": "b-1", "timestamp": 1, "method": method}
    read = REGISTRY.validate(TopicKind.SERVICES, json.dumps({**envelope, "data": "null"}).encode())
    assert read.method == method and read.data.model_dump() == {}
    for wrong in ("NULL", "None", "{}", "x"):
        with pytest.raises(ValidationError):
            REGISTRY.validate(TopicKind.SERVICES, json.dumps({**envelope, "data": wrong}).encode())


def test_the_string_null_is_no_parameters_only_where_none_are_needed() -> None:
    envelope = {"tid": "t-1", "bid": "b-1", "timestamp": 1, "method": "fly_to_point", "data": "null"}
    with pytest.raises(ValidationError) as caught:
        REGISTRY.validate(TopicKind.SERVICES, json.dumps(envelope).encode())
    assert "fly_to_id" in str(caught.value)  # the missing field is named


@pytest.mark.parametrize(
    "address", ["mqtt.dji.com", "mqtt.dji.com:0", "mqtt.dji.com:65536", "a b:1", ":8883"]
)
def test_drc_broker_address_must_be_host_port(address: str) -> None:
    data = _seed(TopicKind.SERVICES, "drc_mode_enter")["data"]
    with pytest.raises(ValidationError):
        DrcModeEnter.model_validate({**data, "mqtt_broker": {**data["mqtt_broker"], "address": address}})
    for good in ("192.0.2.1:8883", "[2001:db8::1]:1883", "mqtt.dji.com:8883"):
        DrcModeEnter.model_validate({**data, "mqtt_broker": {**data["mqtt_broker"], "address": good}})


def test_outbound_result_codes_follow_the_six_digit_rule() -> None:
    event = _seed(TopicKind.EVENTS, "drc_status_notify")
    for good in (0, ResultCode.DRC_HEARTBEAT_TIMEOUT, 336004, 599001):
        event["data"]["result"] = int(good)
        REGISTRY.validate(TopicKind.EVENTS, event)
    for bad in (-1, 1, 4, 425001, 99999, 600000, 3250010):
        event["data"]["result"] = bad
        with pytest.raises(ValidationError):
            REGISTRY.validate(TopicKind.EVENTS, event)


@pytest.mark.parametrize(
    ("raw", "echo"),
    [
        # seed 003: seq in data, echoed in data only
        (
            {"method": "heart_beat", "data": {"seq": 10, "timestamp": 1670415891013}},
            {"method": "heart_beat", "data": {"seq": 10, "timestamp": 1670415891013}},
        ),
        # the newer envelope: seq at the top level, echoed there and in data
        (
            {"seq": 1795807953068, "method": "heart_beat", "data": {"timestamp": 1670415891013}},
            {
                "method": "heart_beat",
                "seq": 1795807953068,
                "data": {"seq": 1795807953068, "timestamp": 1670415891013},
            },
        ),
        # both: the top-level (newer) one wins, in both places
        (
            {"seq": 12, "method": "heart_beat", "data": {"seq": 11, "timestamp": 1670415891013}},
            {"method": "heart_beat", "seq": 12, "data": {"seq": 12, "timestamp": 1670415891013}},
        ),
        # none: none echoed
        (
            {"method": "heart_beat", "data": {"timestamp": 1670415891013}},
            {"method": "heart_beat", "data": {"timestamp": 1670415891013}},
        ),
    ],
)
def test_heart_beat_echo_carries_seq_where_the_request_had_it(
    raw: dict[str, Any], echo: dict[str, Any]
) -> None:
    message = REGISTRY.validate(TopicKind.DRC_DOWN, raw)
    assert json.loads(echo_heart_beat(message).model_dump_json(exclude_none=True)) == echo
