"""Referee-system tables by season, the gateway control messages and the CLI view of both.

The round-trip matrix is derived from the table; the sizes and the hand-packed vectors are not, so a
wrong table entry cannot pass by agreeing with itself."""

from __future__ import annotations

import json
import math
import struct
from typing import Any

import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from adapters.errors import CommandError, UnknownCommandError
from adapters.robomaster import describe
from adapters.robomaster.commands import (
    COMMAND_NAMES,
    CONTROL_COMMANDS,
    CONTROL_TABLE,
    DEFAULT_CONTROL_CMD_ID,
    INTERACTION_MAX_USER_DATA,
    REFEREE_COMMANDS,
    REFEREE_TABLE,
    ROBOT_IDS,
    SEASONS,
    BitLayout,
    Bits,
    ControlChannel,
    Message,
    check_season,
    codec_field_names,
    decode_message,
    decode_payload,
    encode_message,
    encode_payload,
    robot_name,
    robot_team,
    size_range,
)
from adapters.robomaster.protocol import Decoder, Frame, encode_frame
from adapters.wire.layout import Field, Layout, PayloadCodec
from adapters.wire.table import CommandSpec

# PROTOCOL-NOTES, "Command ids change size by season" (2024 = V1.6.1 / 2025 / 2026): what we encode.
NOTES_SIZES: dict[int, tuple[int, int, int]] = {
    0x0001: (11, 11, 11),
    0x0002: (1, 1, 1),
    0x0003: (32, 32, 16),
    0x0101: (4, 4, 4),
    0x0104: (3, 3, 3),
    0x0201: (13, 13, 13),
    0x0202: (16, 16, 14),
    0x0203: (12, 12, 12),
    0x0204: (6, 7, 8),
    0x0206: (1, 1, 1),
    0x0207: (7, 7, 7),
    0x0208: (6, 8, 8),
    0x0209: (4, 4, 5),
    0x020B: (40, 40, 40),
    0x020D: (4, 6, 6),
}

CASES: list[tuple[CommandSpec, str, PayloadCodec]] = [
    (entry, season, codec)
    for name in REFEREE_TABLE.names
    for season in SEASONS
    for entry in [REFEREE_TABLE.named(name, season)]
    for codec in entry.request
]
CASE_IDS = [f"{e.name}-{s}-{size_range(c)[0]}" for e, s, c in CASES]
ENTRY_SEASONS = [(REFEREE_TABLE.named(n, s), s) for n in REFEREE_TABLE.names for s in SEASONS]
ENTRY_SEASON_IDS = [f"{e.name}-{s}" for e, s in ENTRY_SEASONS]


def referee(cmd_id: int, season: str) -> CommandSpec:
    (entry,) = REFEREE_TABLE.at((None, cmd_id), season)
    return entry


def one_frame(raw: bytes) -> Frame:
    dec = Decoder()
    out = dec.feed(raw) + dec.flush()
    assert len(out) == 1 and isinstance(out[0], Frame)
    return out[0]


# --------------------------------------------------------------------------- the table itself


def test_every_notes_entry_is_in_the_table_with_its_season_sizes() -> None:
    for cmd_id, sizes in NOTES_SIZES.items():
        got = tuple(size_range(referee(cmd_id, s).request[0]) for s in SEASONS)
        assert got == tuple((n, n) for n in sizes), REFEREE_COMMANDS[cmd_id]


def test_interaction_is_sub_header_plus_at_most_112_bytes() -> None:
    for season in SEASONS:
        (codec,) = referee(0x0301, season).request
        assert size_range(codec) == (6, 6 + 112)
        assert codec_field_names(codec) == ["data_cmd_id", "sender_id", "receiver_id", "user_data"]


def test_table_entries_are_documented() -> None:
    for entry in REFEREE_TABLE.specs:
        assert entry.name and entry.doc and entry.direction and entry.section
    for name, entries in REFEREE_TABLE.by_name.items():
        assert [e.variant for e in entries] == list(SEASONS), name
    for ctl in CONTROL_COMMANDS.values():
        assert ctl.name and ctl.doc and ctl.direction == "gateway->robot"


def test_command_names_are_unique_and_cover_both_tables() -> None:
    names = list(REFEREE_COMMANDS.values()) + [c.name for c in CONTROL_COMMANDS.values()]
    assert list(COMMAND_NAMES) == names and len(set(names)) == len(names)


@pytest.mark.parametrize(("entry", "season", "codec"), CASES, ids=CASE_IDS)
def test_every_entry_round_trips_in_every_season(
    entry: CommandSpec, season: str, codec: PayloadCodec
) -> None:
    example = codec.example()
    payload = codec.encode(example)
    assert len(payload) == size_range(codec)[0]
    assert decode_payload(entry.cmd_id, payload, season) == Message(entry.name, None, entry.cmd_id, example)
    if codec is entry.request[0]:  # what encode_message emits, through a real frame
        raw = encode_message(entry.name, example, season, seq=42)
        frame = one_frame(raw)
        assert (frame.seq, frame.cmd_id, frame.data) == (42, entry.cmd_id, payload)
        assert decode_message(frame, season) == Message(entry.name, None, entry.cmd_id, example)


def _has_non_finite(fields: dict[str, Any]) -> bool:
    return any(isinstance(v, float) and not math.isfinite(v) for v in fields.values())


@given(st.sampled_from(CASES), st.data())
def test_random_payloads_decode_and_re_encode_bit_exact(
    case: tuple[CommandSpec, str, PayloadCodec], data: st.DataObject
) -> None:
    entry, season, codec = case
    lo, hi = size_range(codec)
    payload = data.draw(st.binary(min_size=lo, max_size=hi))
    msg = decode_payload(entry.cmd_id, payload, season)
    assert msg.name == entry.name
    assume(not _has_non_finite(msg.fields))  # NaN/inf floats decode but are refused on encode
    assert codec.encode(msg.fields) == payload
    if codec is entry.request[0]:
        assert encode_payload(entry.name, msg.fields, season) == (entry.cmd_id, payload)


@pytest.mark.parametrize(("entry", "season"), ENTRY_SEASONS, ids=ENTRY_SEASON_IDS)
def test_wrong_sizes_are_rejected_per_season(entry: CommandSpec, season: str) -> None:
    ranges = [size_range(c) for c in entry.request]
    top = max(hi for _, hi in ranges)
    for n in range(top + 3):
        if any(lo <= n <= hi for lo, hi in ranges):
            continue
        with pytest.raises(CommandError) as info:
            decode_payload(entry.cmd_id, bytes(n), season)
        text = str(info.value)
        assert f"0x{entry.cmd_id:04X}" in text and f"season {season}" in text
        assert f"payload is {n} bytes" in text and "expected" in text
        assert info.value.name == entry.name and info.value.cmd_id == entry.cmd_id


def test_size_error_message_names_everything() -> None:
    with pytest.raises(
        CommandError, match=r"^cmd_id 0x0202 \(power_heat_data\), season 2026: payload is 16 bytes, "
    ):
        decode_payload(0x0202, bytes(16), "2026")
    with pytest.raises(CommandError, match="expected 12 or 16"):
        decode_payload(0x0203, bytes(13), "2025")


def test_a_2024_payload_is_refused_in_2026() -> None:
    hp_2024 = bytes(32)
    assert decode_payload(0x0003, hp_2024, "2024").name == "game_robot_hp"
    with pytest.raises(CommandError, match="expected 16"):
        decode_payload(0x0003, hp_2024, "2026")


# --------------------------------------------------------------------------- hand-packed vectors


def test_game_status_bitfields() -> None:
    payload = bytes([0x41]) + struct.pack("<HQ", 300, 1_700_000_000)
    msg = decode_payload(0x0001, payload, "2024")
    assert msg.fields == {
        "game_type": 1,
        "game_progress": 4,
        "stage_remain_time": 300,
        "sync_time_stamp": 1_700_000_000,
    }
    assert encode_payload("game_status", msg.fields, "2024") == (0x0001, payload)


def test_robot_status_power_output_bits() -> None:
    payload = struct.pack("<BBHHHHHB", 103, 2, 150, 200, 40, 240, 60, 0b1111_1101)
    f = decode_payload(0x0201, payload, "2026").fields
    assert (f["robot_id"], f["robot_level"], f["current_HP"], f["maximum_HP"]) == (103, 2, 150, 200)
    assert (f["shooter_barrel_cooling_value"], f["shooter_barrel_heat_limit"], f["chassis_power_limit"]) == (
        40,
        240,
        60,
    )
    assert f["power_management_gimbal_output"] == 1
    assert f["power_management_chassis_output"] == 0
    assert f["power_management_shooter_output"] == 1
    assert f["power_management_reserved"] == 0b11111
    assert encode_payload("robot_status", f, "2026")[1] == payload


def test_hurt_data_nibbles() -> None:
    assert decode_payload(0x0206, b"\x52", "2025").fields == {"armor_id": 2, "HP_deduction_reason": 5}


def test_power_heat_data_by_season() -> None:
    v2024 = struct.pack("<HHfHHHH", 24000, 1500, 36.0, 60, 10, 20, 30)
    assert decode_payload(0x0202, v2024, "2024").fields == {
        "chassis_voltage": 24000,
        "chassis_current": 1500,
        "chassis_power": 36.0,
        "buffer_energy": 60,
        "shooter_17mm_1_barrel_heat": 10,
        "shooter_17mm_2_barrel_heat": 20,
        "shooter_42mm_barrel_heat": 30,
    }
    v2025 = struct.pack("<HHIHHHH", 0, 0, 0, 60, 10, 20, 30)
    assert decode_payload(0x0202, v2025, "2025").fields["shooter_17mm_2_barrel_heat"] == 20
    v2026 = struct.pack("<HHIHHH", 1, 2, 3, 60, 10, 30)
    assert decode_payload(0x0202, v2026, "2026").fields == {
        "reserved_1": 1,
        "reserved_2": 2,
        "reserved_3": 3,
        "buffer_energy": 60,
        "shooter_17mm_barrel_heat": 10,
        "shooter_42mm_barrel_heat": 30,
    }


def test_robot_pos_twelve_or_sixteen_bytes() -> None:
    xya = struct.pack("<fff", 1.5, 2.25, 90.0)
    assert decode_payload(0x0203, xya, "2026").fields == {"x": 1.5, "y": 2.25, "angle": 90.0}
    long = decode_payload(0x0203, xya + b"\x01\x00\x00\x00", "2026").fields
    assert long == {"x": 1.5, "y": 2.25, "angle": 90.0, "reserved_1": 1}
    assert encode_payload("robot_pos", {"x": 1.5, "y": 2.25, "angle": 90.0}, "2026")[1] == xya


def test_buff_2026_has_a_u16_cooling_buff() -> None:
    payload = struct.pack("<BHBBHB", 10, 400, 50, 30, 100, 0x80)
    assert decode_payload(0x0204, payload, "2026").fields == {
        "recovery_buff": 10,
        "cooling_buff": 400,
        "defence_buff": 50,
        "vulnerability_buff": 30,
        "attack_buff": 100,
        "remaining_energy": 0x80,
    }


def test_game_robot_hp_2026_is_own_side_only() -> None:
    payload = struct.pack("<8H", 200, 250, 300, 350, 0, 400, 1500, 5000)
    f = decode_payload(0x0003, payload, "2026").fields
    assert f["ally_1_robot_HP"] == 200 and f["ally_7_robot_HP"] == 400 and f["ally_base_HP"] == 5000
    f2024 = decode_payload(0x0003, struct.pack("<16H", *range(16)), "2024").fields
    assert f2024["red_5_robot_HP"] == 4 and f2024["blue_base_HP"] == 15


def test_projectile_allowance_fortress_from_2025() -> None:
    payload = struct.pack("<4H", 100, 5, 400, 300)
    assert decode_payload(0x0208, payload, "2025").fields["projectile_allowance_fortress"] == 300
    assert "projectile_allowance_fortress" not in decode_payload(0x0208, payload[:6], "2026").fields


def test_interaction_sub_header_and_tail() -> None:
    payload = struct.pack("<HHH", 0x0201, 3, 7) + b"\xaa\xbb"
    msg = decode_payload(0x0301, payload, "2024")
    assert msg.fields == {"data_cmd_id": 0x0201, "sender_id": 3, "receiver_id": 7, "user_data": b"\xaa\xbb"}
    assert encode_payload("robot_interaction_data", msg.fields, "2024") == (0x0301, payload)
    full = struct.pack("<HHH", 0x0201, 3, 7) + bytes(INTERACTION_MAX_USER_DATA)
    assert len(encode_frame(0x0301, full)) == 127
    with pytest.raises(CommandError, match=r"expected 6\.\.118"):
        decode_payload(0x0301, full + b"\x00", "2026")
    with pytest.raises(ValueError, match="at most 112"):
        encode_payload("robot_interaction_data", {"user_data": bytes(113)}, "2026")


# --------------------------------------------------------------------------- errors


def test_unknown_cmd_id() -> None:
    with pytest.raises(UnknownCommandError, match="0x0999"):
        decode_payload(0x0999, b"", "2026")


def test_unknown_season() -> None:
    assert check_season(2025) == "2025"
    for bad in ("2023", "V1.6.1", ""):
        with pytest.raises(ValueError, match="2024, 2025, 2026"):
            decode_payload(0x0002, b"\x01", bad)
        with pytest.raises(ValueError, match="2024, 2025, 2026"):
            encode_payload("game_result", {"winner": 1}, bad)


def test_unknown_command_name_lists_the_valid_ones() -> None:
    with pytest.raises(ValueError, match=r"game_status.*chassis_velocity"):
        encode_payload("warp_drive", {}, "2026")


def test_fields_of_another_season_are_refused() -> None:
    with pytest.raises(ValueError, match="ally_1_robot_HP"):
        encode_payload("game_robot_hp", {"red_5_robot_HP": 1}, "2026")
    with pytest.raises(ValueError, match="chassis_voltage"):
        encode_payload("power_heat_data", {"shooter_17mm_barrel_heat": 1}, "2024")


@pytest.mark.parametrize("bad", [16, -1, 1.5, "x"])
def test_bitfield_values_are_range_checked(bad: Any) -> None:
    with pytest.raises(ValueError, match="game_type"):
        encode_payload("game_status", {"game_type": bad}, "2026")


def test_bitlayout_must_cover_its_word() -> None:
    with pytest.raises(ValueError, match="add up to 8"):
        BitLayout([Field("w", "B")], {"w": (Bits("a", 3),)})
    with pytest.raises(ValueError, match="unsigned integer"):
        BitLayout([Field("w", "f")], {"w": (Bits("a", 32),)})
    with pytest.raises(ValueError, match="duplicate"):
        BitLayout([Field("a", "B"), Field("w", "B")], {"w": (Bits("a", 8),)})


def test_message_is_frozen_slotted_and_compared_by_value() -> None:
    a = Message("stop", None, DEFAULT_CONTROL_CMD_ID, {"reason": 1})
    assert a == Message("stop", None, DEFAULT_CONTROL_CMD_ID, {"reason": 1})
    assert a != Message("stop", None, DEFAULT_CONTROL_CMD_ID, {"reason": 2})
    assert not hasattr(a, "__dict__")
    with pytest.raises(AttributeError):  # immutable (a named tuple)
        a.name = "x"  # type: ignore[misc]


# --------------------------------------------------------------------------- robot ids


def test_robot_ids() -> None:
    required = {*range(1, 8), 9, 10, 11, *range(101, 108), 109, 110, 111}
    assert required <= set(ROBOT_IDS)
    assert robot_name(1) == "red_hero" and robot_name(107) == "blue_sentry"
    assert (
        robot_name(9) == "red_radar" and robot_name(110) == "blue_outpost" and robot_name(111) == "blue_base"
    )
    assert robot_name(0) is None and robot_name(12) is None and robot_name(100) is None
    assert robot_team(3) == "red" and robot_team(103) == "blue" and robot_team(50) is None


# --------------------------------------------------------------------------- control messages


def test_control_frames_on_the_default_channel() -> None:
    raw = encode_message("chassis_velocity", {"vx": 1.0, "vy": -0.5, "wz": 0.25}, seq=7)
    frame = one_frame(raw)
    assert frame.cmd_id == 0x0F01 == DEFAULT_CONTROL_CMD_ID and frame.seq == 7
    assert frame.data == b"\x01" + struct.pack("<fff", 1.0, -0.5, 0.25)
    assert decode_message(frame) == Message(
        "chassis_velocity", None, 0x0F01, {"vx": 1.0, "vy": -0.5, "wz": 0.25}
    )
    assert one_frame(
        encode_message("gimbal_angle", {"yaw": 0.5, "pitch": -0.125})
    ).data == b"\x02" + struct.pack("<ff", 0.5, -0.125)
    assert one_frame(encode_message("stop", {"reason": 1})).data == b"\x03\x01"
    assert one_frame(encode_message("stop", {})).data == b"\x03\x00"


@pytest.mark.parametrize("ctl", list(CONTROL_COMMANDS.values()), ids=lambda c: c.name)
@pytest.mark.parametrize(
    "channel", [ControlChannel(), ControlChannel(0x1234), ControlChannel(0x0301, 0x02FF, 7, 107)]
)
def test_every_control_message_round_trips(ctl: Any, channel: ControlChannel) -> None:
    example = ctl.request[0].example()
    frame = one_frame(encode_message(ctl.name, example, "2024", seq=3, control=channel))
    assert frame.cmd_id == channel.cmd_id
    for season in SEASONS:
        assert decode_message(frame, season, channel) == Message(ctl.name, None, channel.cmd_id, example)


def test_wrapped_control_uses_the_interaction_sub_header() -> None:
    ch = ControlChannel(0x0301, data_cmd_id=0x0222, sender_id=7, receiver_id=107)
    assert ch.wrapped and not ControlChannel().wrapped
    frame = one_frame(encode_message("stop", {"reason": 2}, control=ch))
    assert frame.cmd_id == 0x0301 and frame.data == struct.pack("<HHH", 0x0222, 7, 107) + b"\x03\x02"
    # without the channel it is ordinary robot interaction data ...
    plain = decode_message(frame)
    assert plain.name == "robot_interaction_data" and plain.fields["user_data"] == b"\x03\x02"
    # ... and other data_cmd_ids stay interaction data even with it
    other = encode_frame(0x0301, struct.pack("<HHH", 0x0223, 7, 107) + b"\x03\x02")
    assert decode_message(one_frame(other), control=ch).name == "robot_interaction_data"


@pytest.mark.parametrize(
    "kwargs",
    [
        {"cmd_id": 0x0203},
        {"cmd_id": 0x0000},
        {"cmd_id": 0x03FF},
        {"cmd_id": 0x0A01},
        {"cmd_id": 0x10000},
        {"cmd_id": 0x0301, "data_cmd_id": 0x0100},
        {"cmd_id": 0x0301, "sender_id": 0x10000},
    ],
)
def test_control_channel_refuses_official_ids(kwargs: dict[str, int]) -> None:
    with pytest.raises(ValueError):
        ControlChannel(**kwargs)


def test_control_payload_errors() -> None:
    with pytest.raises(CommandError, match="unknown message type 0x09") as info:
        decode_payload(0x0F01, b"\x09")
    assert not isinstance(info.value, UnknownCommandError)
    with pytest.raises(CommandError, match="empty body"):
        decode_payload(0x0F01, b"")
    with pytest.raises(CommandError, match=r"chassis_velocity.*1 bytes.*expected 12") as info:
        decode_payload(0x0F01, b"\x01\x00")
    assert info.value.name == "chassis_velocity"
    with pytest.raises(ValueError, match="finite"):
        encode_message("chassis_velocity", {"vx": math.nan})


@given(
    st.floats(width=32, allow_nan=False, allow_infinity=False),
    st.floats(width=32, allow_nan=False, allow_infinity=False),
    st.floats(width=32, allow_nan=False, allow_infinity=False),
    st.integers(0, 255),
)
def test_chassis_velocity_round_trips_any_f32(vx: float, vy: float, wz: float, seq: int) -> None:
    fields = {"vx": vx, "vy": vy, "wz": wz}
    frame = one_frame(encode_message("chassis_velocity", fields, seq=seq))
    assert frame.seq == seq and decode_message(frame).fields == fields


# --------------------------------------------------------------------------- CLI view (describe.py)

RECORD_KEYS = {"protocol", "valid", "seq", "command", "cmd_id", "fields", "error"}


def test_describe_lists_every_command() -> None:
    assert list(COMMAND_NAMES) == describe.COMMANDS


def test_describe_decodes_the_seed_hello_as_an_unknown_command() -> None:
    hello = bytes.fromhex("A5 05 00 00 F6 00 00 68 65 6C 6C 6F 56 34")
    (rec,) = describe.decode_bytes(hello)
    assert set(rec) >= RECORD_KEYS
    assert rec["valid"] is True and rec["seq"] == 0 and rec["cmd_id"] == 0
    assert rec["command"] is None and rec["fields"] is None and rec["error"] is None
    assert rec["payload"] == "68656c6c6f"


def test_describe_reports_garbage_frames_and_payload_problems_in_order() -> None:
    good = encode_message("game_result", {"winner": 2}, seq=5)
    wrong_size = encode_frame(0x0202, bytes(16), seq=6)
    recs = describe.decode_bytes(b"\x00\x01" + good + wrong_size + good[:-1] + b"\xff", season="2026")
    assert [r["valid"] for r in recs] == [False, True, True, False]
    assert recs[0]["error"] == "garbage" and recs[0]["raw"] == "0001"
    assert recs[1]["command"] == "game_result" and recs[1]["fields"] == {"winner": 2} and recs[1]["seq"] == 5
    assert recs[2]["command"] == "power_heat_data" and recs[2]["fields"] is None
    assert "season 2026" in recs[2]["error"] and "expected 14" in recs[2]["error"]
    assert recs[3]["error"] == "frame crc"
    assert all(set(r) >= RECORD_KEYS for r in recs)
    json.dumps(recs)
    assert describe.decode_bytes(wrong_size, season="2024")[0]["error"] is None


@pytest.mark.parametrize("command", COMMAND_NAMES)
@pytest.mark.parametrize("season", SEASONS)
def test_describe_encode_then_decode(command: str, season: str) -> None:
    table = REFEREE_TABLE if command in REFEREE_TABLE.by_name else CONTROL_TABLE
    codec = table.named(command, season).request[0]
    fields = codec.example()
    raw = describe.encode_command(command, 9, fields, season=season)
    (rec,) = describe.decode_bytes(raw, season=season)
    expected = {k: v.hex() if isinstance(v, bytes) else v for k, v in fields.items()}
    assert (rec["valid"], rec["command"], rec["seq"], rec["fields"], rec["error"]) == (
        True,
        command,
        9,
        expected,
        None,
    )
    json.dumps(rec)


def test_describe_takes_hex_for_bytes_fields() -> None:
    fields = {"data_cmd_id": 0x0200, "sender_id": 1, "receiver_id": 3, "user_data": "0102ff"}
    (rec,) = describe.decode_bytes(describe.encode_command("robot_interaction_data", 0, fields))
    assert rec["fields"]["user_data"] == "0102ff"


def test_describe_control_cmd_id_option() -> None:
    raw = describe.encode_command("stop", 1, {"reason": 3}, control_cmd_id=0x0F02)
    assert one_frame(raw).cmd_id == 0x0F02
    (rec,) = describe.decode_bytes(raw, control_cmd_id="0x0F02")
    assert rec["command"] == "stop" and rec["fields"] == {"reason": 3}
    wrapped = describe.encode_command("stop", 1, {"reason": 3}, control_cmd_id=0x0301, control_sender_id=7)
    assert describe.decode_bytes(wrapped, control_cmd_id=0x0301)[0]["command"] == "stop"
    assert describe.decode_bytes(wrapped)[0]["command"] == "robot_interaction_data"


def test_describe_errors_are_value_errors_with_names() -> None:
    with pytest.raises(ValueError, match="game_status"):
        describe.encode_command("nope", 0, {})
    with pytest.raises(ValueError, match="winner"):
        describe.encode_command("game_result", 0, {"loser": 1})
    with pytest.raises(ValueError, match="season"):
        describe.decode_bytes(b"", firmware="new")
    with pytest.raises(ValueError, match="2024, 2025, 2026"):
        describe.encode_command("game_result", 0, {}, season="1999")
    with pytest.raises(ValueError, match="DJI's range"):
        describe.decode_bytes(b"", control_cmd_id=0x0203)


def test_describe_referee_bound_option() -> None:
    big = encode_frame(0x0301, bytes(130))
    assert describe.decode_bytes(big)[0]["valid"] is True
    assert describe.decode_bytes(big, max_data_len=119)[0]["error"] == "data too long"


def test_layout_helpers_reject_foreign_codecs() -> None:
    with pytest.raises(TypeError):
        size_range(object())  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        codec_field_names(object())  # type: ignore[arg-type]
    assert codec_field_names(Layout([Field("a", "B")])) == ["a"]
