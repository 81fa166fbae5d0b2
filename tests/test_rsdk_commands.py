"""R SDK command table: coverage of Figure 4, round trips derived from the table, both reply formats,
errors, and the CLI contract (describe)."""

from __future__ import annotations

import json
import re
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from adapters.errors import CommandError
from adapters.rsdk import describe
from adapters.rsdk.commands import (
    BY_NAME,
    COMMANDS,
    RETURN_CODES,
    TABLE,
    CommandSpec,
    Message,
    TaggedUnion,
    TlvCodec,
    build_frame,
    decode_message,
    decode_reply,
    encode_command,
    lookup,
    payload_examples,
    return_code_text,
    version_text,
    wants_reply,
)
from adapters.rsdk.protocol import Decoder, Frame, encode
from adapters.wire.layout import Field, Layout

FIGURE_4 = {(0x0E, i) for i in range(0x13)} | {(0x0D, 0x00), (0x0D, 0x01)}
BRIEF_NAMES = {
    "position_control",
    "speed_control",
    "get_angle",
    "set_limit_angle",
    "get_limit_angle",
    "set_stiffness",
    "get_stiffness",
    "push_settings",
    "param_push",
    "get_version",
    "version_push",
    "external_control",
    "get_user_params",
    "set_user_params",
    "set_operating_mode",
    "recenter_selfie",
    "follow_mode",
    "auto_calibration",
    "calibration_push",
    "active_track",
    "focus_motor",
    "camera_control",
    "camera_status",
}
# the seed's "This command has no reply frame" entries, and 0x0F/0x11, which it draws without a reply row
NO_REPLY = {
    "param_push",
    "version_push",
    "external_control",
    "calibration_push",
    "auto_calibration",
    "active_track",
}


def decode_one(raw: bytes) -> Frame:
    d = Decoder()
    out = d.feed(raw) + d.flush()
    assert len(out) == 1 and isinstance(out[0], Frame), out
    return out[0]


def matrix(reply: bool) -> list[Any]:
    return [
        pytest.param(spec, ex, id=f"{spec.name}-{i}")
        for spec in BY_NAME.values()
        for i, ex in enumerate(payload_examples(spec, reply=reply))
    ]


# --- the table -----------------------------------------------------------------------------------


def test_table_covers_figure_4() -> None:
    assert set(TABLE) == FIGURE_4


def test_names() -> None:
    assert set(COMMANDS) == BRIEF_NAMES
    assert len(COMMANDS) == len(set(COMMANDS))
    assert all(re.fullmatch(r"[a-z][a-z0-9_]*", n) for n in COMMANDS)


def test_entries_are_declared_completely() -> None:
    for key, entries in TABLE.items():
        for spec in entries:
            assert spec.key == key
            assert re.fullmatch(r"2\.3\.[45]\.\d+", spec.section), spec.name
            assert spec.direction
    assert {n for n, s in BY_NAME.items() if not s.reply} == NO_REPLY


def _layouts(codec: Any) -> list[Layout]:
    if isinstance(codec, Layout):
        return [codec]
    if isinstance(codec, TaggedUnion):
        return [codec.head, *(a for arm in codec.arms.values() for a in arm)]
    if isinstance(codec, TlvCodec):
        return [codec.head, *(p.value for p in codec.params.values())]
    raise AssertionError(codec)


def test_every_reply_starts_with_return_code() -> None:
    for spec in BY_NAME.values():
        if spec.reply:
            reply = spec.reply[0]
            head = reply.head if isinstance(reply, TaggedUnion | TlvCodec) else reply
            assert head.fields[0].name == "return_code", spec.name


def test_field_names_are_snake_case_and_typos_fixed() -> None:
    names = {
        f.name
        for s in BY_NAME.values()
        for c in (*s.request, *s.reply)
        for lay in _layouts(c)
        for f in lay.fields
    }
    assert all(re.fullmatch(r"[a-z][a-z0-9_]*", n) for n in names), names
    assert not any("agnle" in n for n in names)
    push = BY_NAME["param_push"].request[0]
    assert isinstance(push, Layout) and push.size == 22  # 40-byte frame
    assert [f.name for f in push.fields][4:7] == ["yaw_joint_angle", "roll_joint_angle", "pitch_joint_angle"]


def test_seed_ranges() -> None:
    pos = BY_NAME["position_control"].request[0]
    assert isinstance(pos, Layout)
    r = {f.name: (f.minimum, f.maximum) for f in pos.fields}
    assert (
        r["yaw_angle"] == (-1800, 1800)
        and r["roll_angle"] == (-300, 300)
        and r["pitch_angle"] == (-560, 1460)
    )


def test_return_codes() -> None:
    assert set(RETURN_CODES) == {0x00, 0x01, 0x02, 0xFF}
    assert return_code_text(0) == "command execution succeeds"
    assert "0x07" in return_code_text(7)


def test_version_text() -> None:
    assert version_text(0x01020304) == "01.02.03.04"
    assert version_text(0xAABBCCDD) == "AA.BB.CC.DD"


# --- round trips derived from the table ----------------------------------------------------------


def test_seed_sample_from_table() -> None:
    raw = encode_command(
        "position_control",
        0x1122,
        {"yaw_angle": 0x20, "roll_angle": 0x30, "pitch_angle": 0x40, "ctrl_byte": 1, "time_for_action": 20},
    )
    assert raw == bytes.fromhex("AA1A0003000000002211A2420E0020003000400001147B4097BE")


@pytest.mark.parametrize(("spec", "fields"), matrix(reply=False))
def test_command_round_trip(spec: CommandSpec, fields: dict[str, Any]) -> None:
    frame = decode_one(encode_command(spec.name, 0x1234, fields))
    assert frame.seq == 0x1234 and not frame.is_reply and frame.key == spec.key
    assert frame.cmd_type == (0x03 if wants_reply(spec, fields) else 0x00)
    assert decode_message(frame) == Message(spec.name, spec.cmd_set, spec.cmd_id, fields)


@pytest.mark.parametrize(("spec", "fields"), matrix(reply=True))
def test_reply_round_trip_latest(spec: CommandSpec, fields: dict[str, Any]) -> None:
    raw = encode_command(spec.name, 0x0102, fields, reply=True)
    assert raw[3] & 0x20
    frame = decode_one(raw)
    assert frame.is_reply and frame.key == spec.key
    msg = decode_reply(frame, spec.cmd_set, spec.cmd_id, spec.name)
    assert msg == Message(spec.name, spec.cmd_set, spec.cmd_id, fields, is_reply=True, legacy=False)
    plain = decode_message(frame)  # without context: latest format, first entry at the key
    assert plain.fields == fields and plain.name in {e.name for e in TABLE[spec.key]}


@pytest.mark.parametrize(("spec", "fields"), matrix(reply=True))
def test_reply_round_trip_legacy(spec: CommandSpec, fields: dict[str, Any]) -> None:
    latest = encode_command(spec.name, 9, fields, reply=True)
    raw = encode_command(spec.name, 9, fields, reply=True, legacy=True)
    assert len(raw) == len(latest) - 2
    frame = decode_one(raw)
    msg = decode_reply(frame, spec.cmd_set, spec.cmd_id, spec.name)
    assert msg == Message(spec.name, spec.cmd_set, spec.cmd_id, fields, is_reply=True, legacy=True)
    with pytest.raises(CommandError):
        decode_message(frame)  # no CmdSet/CmdID: needs the sent command


def _field_st(f: Field) -> st.SearchStrategy[Any]:
    if f.code == "s":
        return st.binary(min_size=f.count, max_size=f.count)
    lo, hi = {"B": (0, 255), "b": (-128, 127), "H": (0, 0xFFFF), "h": (-0x8000, 0x7FFF), "I": (0, 2**32 - 1)}[
        f.code
    ]
    return st.integers(
        int(f.minimum if f.minimum is not None else lo), int(f.maximum if f.maximum is not None else hi)
    )


def _layout_st(layout: Layout) -> st.SearchStrategy[dict[str, Any]]:
    return st.fixed_dictionaries({f.name: _field_st(f) for f in layout.fields})


def _tlv_item_st(codec: TlvCodec) -> st.SearchStrategy[dict[str, Any]]:
    def item(p: Any) -> st.SearchStrategy[dict[str, Any]]:
        one = len(p.value.fields) == 1
        value = _field_st(p.value.fields[0]) if one else _layout_st(p.value)
        return value.map(lambda v: {"id": p.id, "name": p.name, "length": p.value.size, "value": v})

    unknown = st.tuples(st.integers(0x30, 0xFF), st.binary(max_size=6)).map(
        lambda t: {"id": t[0], "name": None, "length": len(t[1]), "value": t[1]}
    )
    return st.one_of(*(item(p) for p in codec.params.values()), unknown)


def codec_st(codec: Any) -> st.SearchStrategy[dict[str, Any]]:
    """Random in-range fields for any table codec (Layout, TaggedUnion, TlvCodec)."""
    if isinstance(codec, TaggedUnion):
        return st.one_of(
            *(
                st.tuples(_layout_st(codec.head), _layout_st(arm[0])).map(
                    lambda t, tag=tag: {**t[0], codec.tag: tag, **t[1]}
                )
                for tag, arm in codec.arms.items()
            )
        )
    if isinstance(codec, TlvCodec):
        return st.tuples(_layout_st(codec.head), st.lists(_tlv_item_st(codec), max_size=4)).map(
            lambda t: {**t[0], codec.name: t[1]}
        )
    assert isinstance(codec, Layout)
    if codec.tail is not None:  # read_ids
        return st.lists(st.integers(0, 255), min_size=1, max_size=8).map(lambda ids: {"read_ids": ids})
    return _layout_st(codec)


@st.composite
def table_case(draw: st.DrawFn) -> tuple[CommandSpec, bool, dict[str, Any]]:
    spec = draw(st.sampled_from(list(BY_NAME.values())))
    reply = bool(spec.reply) and draw(st.booleans())
    codec = spec.reply[0] if reply else spec.request[0]
    fields = draw(codec_st(codec))
    if not reply:
        fields = {**fields, **spec.fixed}
    return spec, reply, fields


@given(table_case(), st.integers(0, 0xFFFF), st.booleans())
def test_table_round_trip_hypothesis(
    case: tuple[CommandSpec, bool, dict[str, Any]], seq: int, legacy: bool
) -> None:
    spec, reply, fields = case
    raw = encode_command(spec.name, seq, fields, reply=reply, legacy=reply and legacy)
    frame = decode_one(raw)
    msg = decode_reply(frame, *spec.key, name=spec.name) if reply else decode_message(frame)
    assert (msg.name, msg.fields, msg.is_reply) == (spec.name, fields, reply)


# --- both reply formats --------------------------------------------------------------------------


def test_legacy_and_latest_lengths_match_real_drivers() -> None:
    """ArduPilot expects 17/19-byte position replies and 24/26-byte attitude replies."""
    ok = {"return_code": 0}
    assert len(encode_command("position_control", 1, ok, reply=True, legacy=True)) == 17
    assert len(encode_command("position_control", 1, ok, reply=True)) == 19
    angles = {"return_code": 0, "data_type": 1, "yaw": -900, "roll": 5, "pitch": 300}
    legacy = decode_one(encode_command("get_angle", 2, angles, reply=True, legacy=True))
    latest = decode_one(encode_command("get_angle", 2, angles, reply=True))
    assert len(encode(legacy)) == 24 and len(encode(latest)) == 26
    assert decode_reply(legacy, 0x0E, 0x02).fields == decode_reply(latest, 0x0E, 0x02).fields == angles
    assert decode_reply(legacy, 0x0E, 0x02).legacy and not decode_reply(latest, 0x0E, 0x02).legacy


def test_latest_reply_for_another_command_is_rejected() -> None:
    frame = decode_one(
        encode_command(
            "get_limit_angle",
            5,
            {
                "return_code": 0,
                **dict.fromkeys(["pitch_max", "pitch_min", "yaw_max", "yaw_min", "roll_max", "roll_min"], 1),
            },
            reply=True,
        )
    )
    with pytest.raises(CommandError, match="neither format"):
        decode_reply(frame, 0x0E, 0x00)  # sent position_control: fits neither
    with pytest.raises(CommandError, match="not a reply"):
        decode_reply(decode_one(encode_command("get_angle", 1, {"ctrl_byte": 1})), 0x0E, 0x02)
    with pytest.raises(CommandError, match="no reply frame"):
        decode_reply(frame, 0x0E, 0x08)


def test_decode_message_explains_legacy_reply() -> None:
    frame = decode_one(
        encode_command(
            "get_stiffness",
            5,
            {"return_code": 0, "pitch_stiffness": 1, "yaw_stiffness": 2, "roll_stiffness": 3},
            reply=True,
            legacy=True,
        )
    )
    with pytest.raises(CommandError, match="decode_reply"):
        decode_message(frame)


# --- shared keys, unions, TLV --------------------------------------------------------------------


def test_version_query_vs_push_by_length() -> None:
    q = decode_message(decode_one(encode_command("get_version", 1, {"device_id": 1})))
    p = decode_message(decode_one(encode_command("version_push", 1, {"device_id": 1, "version": 0x01020304})))
    assert (q.name, p.name) == ("get_version", "version_push")
    assert build_frame("get_version", 1, {"device_id": 1}).cmd_type == 0x03
    assert build_frame("version_push", 1, {"device_id": 1, "version": 2}).cmd_type == 0x00


def test_recenter_vs_follow_mode() -> None:
    raw = encode_command("recenter_selfie", 1, {"recenter_and_selfie_command": 1})  # operating_mode filled
    assert decode_message(decode_one(raw)) == Message(
        "recenter_selfie", 0x0E, 0x0E, {"operating_mode": 0xFE, "recenter_and_selfie_command": 1}
    )
    raw = encode_command("follow_mode", 1, {"operating_mode": 3, "recenter_and_selfie_command": 0})
    assert decode_message(decode_one(raw)).name == "follow_mode"
    with pytest.raises(CommandError, match="operating_mode"):
        encode_command("follow_mode", 1, {"operating_mode": 0xFE, "recenter_and_selfie_command": 0})
    with pytest.raises(CommandError, match="operating_mode"):
        encode_command("recenter_selfie", 1, {"operating_mode": 2, "recenter_and_selfie_command": 1})


def test_external_control_union() -> None:
    joy = {"device_type": 1, "pitch_speed": -15000, "roll_speed": 0, "yaw_speed": 15000}
    raw = encode_command("external_control", 3, joy)
    assert raw[3] == 0x00  # no reply frame
    assert decode_message(decode_one(raw)).fields == joy
    dial = {"device_type": 2, "dial_speed": -2048}
    assert decode_message(decode_one(encode_command("external_control", 3, dial))).fields == dial
    with pytest.raises(CommandError, match="device_type"):
        encode_command("external_control", 3, {"device_type": 3})
    with pytest.raises(CommandError, match="unknown field"):
        encode_command("external_control", 3, {**dial, "pitch_speed": 1})
    bad = decode_one(encode(Frame(0x0E, 0x0A, b"\x05\x00\x00")))
    with pytest.raises(CommandError, match="device_type"):
        decode_message(bad)


def test_focus_motor_reply_per_sub_command() -> None:
    assert (
        build_frame(
            "focus_motor",
            1,
            {"command_sub_id": 1, "control_type": 0, "data_length": 2, "absolute_position": 4095},
        ).cmd_type
        == 0x00
    )
    assert build_frame("focus_motor", 1, {"command_sub_id": 0x15, "motor_type": 0}).cmd_type == 0x03
    with pytest.raises(CommandError, match="absolute_position"):
        encode_command(
            "focus_motor",
            1,
            {"command_sub_id": 1, "control_type": 0, "data_length": 2, "absolute_position": 4096},
        )
    pos = {
        "return_code": 0,
        "command_sub_id": 0x15,
        "motor_type": 0,
        "endpoints_calibration_status": 3,
        "current_position": 2048,
    }
    frame = decode_one(encode_command("focus_motor", 1, pos, reply=True))
    assert decode_reply(frame, 0x0E, 0x12).fields == pos


def test_tlv_user_params() -> None:
    cmd = encode_command("get_user_params", 1, {"read_ids": [0x22, 0x23]})
    assert decode_one(cmd).payload == b"\x22\x23"
    assert encode_command("get_user_params", 1, {"read_ids": "2223"}) == cmd
    with pytest.raises(CommandError, match="at least one"):
        encode_command("get_user_params", 1, {"read_ids": []})
    reply = decode_one(encode(Frame(0x0E, 0x0B, bytes.fromhex("00 2201 08 7703 010203"), is_reply=True)))
    msg = decode_reply(reply, 0x0E, 0x0B)
    assert msg.fields == {
        "return_code": 0,
        "tlv_buffer": [
            {"id": 0x22, "name": "special_functions_under_follow_mode", "length": 1, "value": 8},
            {"id": 0x77, "name": None, "length": 3, "value": b"\x01\x02\x03"},
        ],
    }
    by_name = encode_command(
        "set_user_params", 1, {"tlv_buffer": [{"name": "motor_special_function", "value": 1}]}
    )
    assert decode_one(by_name).payload == b"\x23\x01\x01"
    raw_value = encode_command("set_user_params", 1, {"tlv_buffer": [{"id": 0x40, "value": "0a0b"}]})
    assert decode_one(raw_value).payload == b"\x40\x02\x0a\x0b"
    for bad, match in [
        ([{"id": 0x40, "value": 3}], "hex"),
        ([{"id": 0x23, "value": 1, "length": 2}], "length"),
        ([{"name": "nope", "value": 1}], "unknown TLV name"),
        ([{"id": 0x00, "value": 9}], "seed range"),
        ([{"id": 0x00}], "no value"),
    ]:
        with pytest.raises(CommandError, match=match):
            encode_command("set_user_params", 1, {"tlv_buffer": bad})
    cut = decode_one(encode(Frame(0x0E, 0x0B, bytes.fromhex("00 2205 01"), is_reply=True)))
    with pytest.raises(CommandError, match="announces 5 bytes"):
        decode_reply(cut, 0x0E, 0x0B)


def test_calibration_push_value_decoded() -> None:
    frame = decode_one(encode(Frame(0x0E, 0x10, bytes.fromhex("0006 01 2a 00000102"), cmd_type=0)))
    msg = decode_message(frame)
    assert msg.name == "calibration_push"
    assert msg.fields["tlv_buffer"] == [
        {
            "id": 0,
            "name": "control_parameters_self_tuning",
            "length": 6,
            "value": {"status": 1, "progress": 42, "error": b"\x00\x00\x01\x02"},
        }
    ]
    item = {"id": 0, "value": {"status": 2, "progress": 100, "error": "00000000"}}  # hex for bytes (CLI)
    assert decode_one(encode_command("calibration_push", 2, {"tlv_buffer": [item]})).payload == bytes.fromhex(
        "0006 02 64 00000000"
    )


# --- errors --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("command", "fields", "match"),
    [
        ("no_such", {}, "valid: position_control"),
        ("get_angle", {"ctrl_byte": 1, "extra": 2}, "unknown field"),
        ("position_control", {"yaw_angle": 0}, "missing field"),
        (
            "position_control",
            {"yaw_angle": 1801, "roll_angle": 0, "pitch_angle": 0, "ctrl_byte": 1, "time_for_action": 1},
            "yaw_angle: 1801 outside seed range",
        ),
        ("get_angle", {"ctrl_byte": "x"}, "ctrl_byte"),
        ("param_push", {}, "missing"),
    ],
)
def test_encode_errors(command: str, fields: dict[str, Any], match: str) -> None:
    with pytest.raises(CommandError, match=match):
        encode_command(command, 1, fields)
    with pytest.raises(ValueError, match=match):
        describe.encode_command(command, 1, fields)


def test_reply_errors_and_lookup() -> None:
    with pytest.raises(CommandError, match="no reply frame"):
        encode_command("param_push", 1, {}, reply=True)
    with pytest.raises(CommandError, match="seq"):
        encode_command("get_angle", 0x10000, {"ctrl_byte": 1})
    assert lookup((0x0E, 0x09)).name == "get_version"
    assert lookup((0x0E, 0x0E)).name == "recenter_selfie"
    with pytest.raises(CommandError, match="unknown command key"):
        lookup((0x0E, 0x13))


def test_payload_that_does_not_fit() -> None:
    frame = decode_one(encode(Frame(0x0E, 0x00, bytes(7))))
    with pytest.raises(CommandError, match="7 bytes, layout needs 8"):
        decode_message(frame)
    with pytest.raises(CommandError, match="unknown command 0x0E 0x13"):
        decode_message(decode_one(encode(Frame(0x0E, 0x13, b""))))


# --- CLI contract (describe) ---------------------------------------------------------------------

KEYS = {"protocol", "valid", "seq", "command", "fields", "error", "cmd_set", "cmd_id", "is_reply"}


def test_describe_commands_list() -> None:
    assert describe.COMMANDS == COMMANDS


def test_describe_decode_stream_with_legacy_reply_matched_by_seq() -> None:
    cmd = describe.encode_command("get_angle", 77, {"ctrl_byte": 1})
    rep = describe.encode_command(
        "get_angle",
        77,
        {"return_code": 0, "data_type": 1, "yaw": 1, "roll": 2, "pitch": 3},
        reply=True,
        legacy=True,
    )
    unknown = encode(Frame(0x0E, 0x13, b"\x01\x02"))
    unfit = encode(Frame(0x0E, 0x00, b"\x01"))
    out = describe.decode_bytes(b"\x00" + cmd + rep + unknown + unfit + b"\xaa")
    json.dumps(out)
    assert all(set(d) >= KEYS for d in out)
    assert [d["valid"] for d in out] == [False, True, True, True, True, False]
    assert out[0]["error"] == "garbage" and out[-1]["error"] == "truncated"
    assert (
        out[1]["command"] == "get_angle" and out[1]["fields"] == {"ctrl_byte": 1} and out[1]["error"] is None
    )
    assert out[2]["command"] == "get_angle" and out[2]["is_reply"] and out[2]["legacy"]
    assert out[2]["cmd_set"] == 0x0E and out[2]["cmd_id"] == 0x02
    assert out[2]["text"] == {"return_code": "command execution succeeds"}
    assert out[3]["command"] is None and out[3]["fields"] is None and out[3]["payload"] == "0e130102"
    assert out[4]["valid"] and out[4]["fields"] is None and "layout needs 8" in out[4]["error"]


def test_describe_reply_to_option_and_bytes_as_hex() -> None:
    rep = describe.encode_command(
        "camera_status", 1, {"return_code": 0, "camera_status": 2}, reply=True, legacy=True
    )
    (alone,) = describe.decode_bytes(rep)
    assert alone["command"] is None and "decode_reply" in alone["error"]
    (matched,) = describe.decode_bytes(rep, reply_to="camera_status")
    assert matched["fields"] == {"return_code": 0, "camera_status": 2} and matched["legacy"]
    push = describe.encode_command(
        "calibration_push",
        1,
        {"tlv_buffer": [{"id": 0, "value": {"status": 3, "progress": 0, "error": "01020304"}}]},
    )
    (d,) = describe.decode_bytes(push)
    assert d["fields"]["tlv_buffer"][0]["value"]["error"] == "01020304"
    json.dumps(d)


def test_describe_version_text_and_options() -> None:
    rep = describe.encode_command(
        "get_version", 1, {"return_code": 0, "device_id": 1, "version": 0x01040020}, reply=True
    )
    (d,) = describe.decode_bytes(rep)
    assert d["text"] == {
        "return_code": "command execution succeeds",
        "device_id": "DJI R SDK",
        "version": "01.04.00.20",
    }
    with pytest.raises(ValueError, match="unknown option"):
        describe.decode_bytes(rep, bogus=1)
    with pytest.raises(ValueError, match="unknown option"):
        describe.encode_command("get_angle", 1, {"ctrl_byte": 1}, bogus=1)
    with pytest.raises(ValueError, match="valid:"):
        describe.decode_bytes(rep, reply_to="nope")


def test_legacy_angle_reply_in_either_order() -> None:
    """Seed 000 §2.3.4.3: reply data = return code, data_type, yaw, roll, pitch (int16 LE, 0.1°). A legacy
    reply (no CmdSet/CmdID) from older firmware may carry yaw, pitch, roll (ArduPilot's reading)."""
    from adapters.rsdk import commands as cmds
    from adapters.rsdk.protocol import Decoder

    # yaw 30.0°, second slot 5.0°, third slot 20.0°
    data = bytes.fromhex("00 01 2c01 3200 c800")
    legacy = cmds.encode_command("get_angle", 7, {"return_code": 0, "data_type": 1, "yaw": 300, "roll": 50,
                                                  "pitch": 200}, reply=True, legacy=True)  # fmt: skip
    swapped = cmds.encode_command("get_angle", 7, {"return_code": 0, "data_type": 1, "yaw": 300, "roll": 200,
                                                   "pitch": 50}, reply=True, legacy=True,
                                  angle_order="yaw_pitch_roll")  # fmt: skip
    assert legacy == swapped  # the same bytes: roll 5° / pitch 20° vs roll 20° / pitch 5°
    frame = Decoder().feed(legacy)[0]
    assert frame.data == data
    seed = cmds.decode_reply(frame, 0x0E, 0x02)
    assert seed.legacy and (seed.fields["roll"], seed.fields["pitch"]) == (50, 200)
    other = cmds.decode_reply(frame, 0x0E, 0x02, angle_order="yaw_pitch_roll")
    assert (other.fields["yaw"], other.fields["roll"], other.fields["pitch"]) == (300, 200, 50)
    # the latest form follows the seed whatever the setting
    fields = {"return_code": 0, "data_type": 1, "yaw": 300, "roll": 50, "pitch": 200}
    latest = Decoder().feed(cmds.encode_command("get_angle", 8, fields, reply=True))[0]
    assert cmds.decode_reply(latest, 0x0E, 0x02, angle_order="yaw_pitch_roll").fields["roll"] == 50
    with pytest.raises(CommandError, match="legacy angle order"):
        cmds.decode_reply(frame, 0x0E, 0x02, angle_order="pitch_yaw_roll")
