"""OSDK command table: packed sizes from seed 004 and PROTOCOL-NOTES, every entry's request and ACK
layouts round-tripping, union shapes, ACK code texts, firmware variants, and the CLI contract."""

from __future__ import annotations

import contextlib
import json
import math
import re
import struct
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from adapters.errors import UnknownCommandError
from adapters.osdk import commands as c
from adapters.osdk import describe
from adapters.osdk.commands import (
    BY_NAME,
    COMMAND_NAMES,
    GS_ACK_CODES,
    TABLE,
    CommandSpec,
    decode_ack,
    decode_request,
    encode_ack_payload,
    encode_request,
    encode_version_reply,
    examples_of,
    parse_version_reply,
    spec_for,
)
from adapters.osdk.protocol import SessionMode, decode_frame, encode_ack, encode_command
from adapters.wire.layout import Field, Layout, LayoutError
from adapters.wire.table import Delivery

ALL_SPECS: list[CommandSpec] = [s for specs in TABLE.values() for s in specs]


def _id(spec: CommandSpec) -> str:
    return f"{spec.name}-{spec.variant or 'any'}"


def _fields(spec: CommandSpec) -> list[Field]:
    return [f for codec in spec.request if isinstance(codec, Layout) for f in codec.fields]


def _firmwares(spec: CommandSpec) -> list[str]:
    return [spec.variant] if spec.variant else ["new", "m100"]


# ---------------------------------------------------------------------------------------------- table


def test_required_names_exist_and_are_unique_snake_case() -> None:
    required = {
        "wp_init", "wp_upload", "wp_start_stop", "wp_pause_resume", "wp_download_init", "wp_download_point",
        "wp_set_idle_velocity", "wp_get_idle_velocity", "hp_upload_start", "hp_stop", "hp_pause_resume",
        "hp_set_idle_velocity", "hp_set_radius", "hp_reset_yaw", "hp_download", "hp_auto_radius",
        "fm_upload_start", "fm_stop", "fm_pause_resume", "fm_update_target", "status_push", "event_push",
        "activate", "get_version", "set_broadcast_frequency", "obtain_control", "flight_task",
        "movement_control", "emergency_brake", "arm", "kill_switch", "flight_data_push",
        "lost_authority_push",
    }  # fmt: skip
    assert required <= set(COMMAND_NAMES)
    assert len(set(COMMAND_NAMES)) == len(COMMAND_NAMES)
    assert all(re.fullmatch(r"[a-z][a-z0-9_]*", n) for n in COMMAND_NAMES)
    assert list(COMMAND_NAMES) == describe.COMMANDS
    # a name maps to one spec per firmware
    for name, specs in BY_NAME.items():
        fws = [fw for s in specs for fw in _firmwares(s)]
        assert len(fws) == len(set(fws)), name


def test_table_keys_and_session_rules() -> None:
    for key, specs in TABLE.items():
        assert all(s.key == key for s in specs)
        for s in specs:
            assert s.section and s.direction in (c.TO_FC, c.FROM_FC)
            if s.delivery.session == SessionMode.NO_ACK and s.direction == c.TO_FC:
                assert not s.reply, s.name  # session 0 means nobody answers
    ground_station = [s for s in ALL_SPECS if s.cmd_set == 0x03]
    assert sorted(s.cmd_id for s in ground_station) == [
        *range(0x10, 0x18),
        *range(0x20, 0x28),
        *range(0x30, 0x34),
    ]
    for s in ground_station:
        if s.name == "fm_update_target":
            assert (s.reply, s.delivery.session) == ((), SessionMode.NO_ACK)  # seed: NO ACK
        else:
            assert s.delivery == Delivery(SessionMode.ACK_REQUIRED, 0.5, 2)
            assert s.reply and s.reply_codes == c.GS_ACK_TEXT
    assert (spec_for("activate").delivery.timeout, spec_for("activate").delivery.retries) == (1.0, 3)
    assert spec_for("movement_control").delivery.session == SessionMode.NO_ACK


@pytest.mark.parametrize(
    ("name", "sizes", "ack_sizes"),
    [
        ("wp_init", [51], [1]),
        ("wp_upload", [90, 87], [2]),
        ("wp_start_stop", [1], [1]),
        ("wp_download_init", [1], [52]),
        ("wp_download_point", [1], [91, 88]),
        ("wp_set_idle_velocity", [4], [5]),
        ("wp_get_idle_velocity", [1], [5]),
        ("hp_upload_start", [51], [5]),
        ("hp_set_idle_velocity", [5], [1]),
        ("hp_download", [1], [52, 53]),
        ("hp_auto_radius", [2], [1]),
        ("fm_upload_start", [23], [1]),
        ("fm_update_target", [20], []),
        ("status_push", [6], []),
        ("activate", [44], [2]),
        ("get_version", [1], [None]),
        ("set_broadcast_frequency", [16], [2]),
        ("obtain_control", [1], [2]),
        ("flight_task", [1], [2]),
        ("movement_control", [17], []),
        ("emergency_brake", [26], []),
        ("arm", [1], [2]),
        ("kill_switch", [13], [2]),
        ("lost_authority_push", [1], [2]),
        ("subscribe_verify", [4], [1]),
        ("subscribe_add_package", [None], [1]),
        ("subscribe_reset", [1], [1]),
        ("subscribe_remove_package", [1], [1]),
        ("subscription_data_push", [None], []),
        ("go_home_altitude_write", [6], [7, 13]),
        ("go_home_altitude_read", [4], [7, 13]),
    ],
)
def test_packed_sizes(name: str, sizes: list[int], ack_sizes: list[int | None]) -> None:
    spec = spec_for(name)
    assert [r.size for r in spec.request] == sizes
    assert [a.size for a in spec.reply] == ack_sizes


@pytest.mark.parametrize("spec", ALL_SPECS, ids=_id)
def test_every_request_layout_round_trips(spec: CommandSpec) -> None:
    for firmware in _firmwares(spec):
        for codec in spec.request:
            for example in examples_of(codec):
                values = {**example, **spec.fixed}
                payload = codec.encode(values)
                msg = decode_request(spec.cmd_set, spec.cmd_id, payload, firmware)
                assert (msg.name, msg.is_reply) == (spec.name, False)
                assert msg.fields == values
                # and through a real frame
                frame = decode_frame(
                    encode_command(spec.cmd_set, spec.cmd_id, payload, spec.delivery.session, 3)
                )
                assert frame.payload == payload


@pytest.mark.parametrize("spec", [s for s in ALL_SPECS if s.reply], ids=_id)
def test_every_ack_layout_round_trips(spec: CommandSpec) -> None:
    for firmware in _firmwares(spec):
        for codec in spec.reply:
            for example in examples_of(codec):
                data = codec.encode(example)
                msg = decode_ack(spec.name, data, firmware)
                assert (msg.name, msg.is_reply, msg.fields) == (spec.name, True, example)
                assert decode_frame(encode_ack(2, 9, data)).payload == data


def test_specs_without_ack_refuse_ack_helpers() -> None:
    with pytest.raises(LayoutError, match="takes no ACK"):
        decode_ack("movement_control", b"\0")
    with pytest.raises(LayoutError, match="takes no ACK"):
        encode_ack_payload("fm_update_target", {})


# ---------------------------------------------------------------------------------------------- waypoints


def _waypoint(slots: int) -> dict[str, Any]:
    return {
        "index": 3,
        "latitude": 0.39269908169872414,
        "longitude": 1.9896753472735356,
        "altitude": 50.5,
        "damping_dis": 2.0,
        "tgt_yaw": -90,
        "tgt_gimbal_pitch": -45,
        "turn_mode": 1,
        "resv": bytes(8),
        "has_action": 1,
        "action_time_limit": 100,
        "action_num": 3,
        "action_rpt": 2,
        "command_list": [1, 4, 5] + [0] * (slots - 3),
        "command_param": [0, -180, -90] + [0] * (slots - 3),
    }


def test_waypoint_90_bytes_byte_layout() -> None:
    values = _waypoint(16)
    payload = encode_request("wp_upload", values)
    assert len(payload) == 90
    assert payload[0] == 3  # leading index
    assert struct.unpack_from("<ddffhhB", payload, 1) == (
        values["latitude"],
        values["longitude"],
        50.5,
        2.0,
        -90,
        -45,
        1,
    )
    assert payload[30:38] == bytes(8)  # resv
    assert (payload[38], struct.unpack_from("<H", payload, 39)[0]) == (1, 100)
    assert payload[41] == 2 << 4 | 3  # action_num : 4 (low), action_rpt : 4 (high)
    assert list(payload[42:58]) == values["command_list"]
    assert list(struct.unpack_from("<16h", payload, 58)) == values["command_param"]
    assert decode_request(0x03, 0x11, payload).fields == values


def test_waypoint_87_bytes_seed_shape_decodes() -> None:
    values = _waypoint(15)
    payload = c.WAYPOINT_SEED.encode(values)
    assert len(payload) == 87  # index + the seed's 86-byte struct with 15-slot arrays
    assert payload[41] == 2 << 4 | 3
    assert decode_request(0x03, 0x11, payload).fields == values
    # the seed's download ACK {ack, index, waypoint_comm_t} is 88 bytes; the notes' {ack, 90-byte} is 91
    assert decode_ack("wp_download_point", b"\x00" + payload).fields == {"ack": 0, **values}
    big = _waypoint(16)
    assert decode_ack("wp_download_point", b"\xe1" + encode_request("wp_upload", big)).fields == {
        "ack": 0xE1,
        **big,
    }


def test_waypoint_rejects_bad_sizes_and_nibbles() -> None:
    with pytest.raises(LayoutError, match="fits none of wp_upload: 90 or 87 bytes"):
        decode_request(0x03, 0x11, bytes(86))
    with pytest.raises(LayoutError, match="action_num: 16 does not fit 4 bit"):
        encode_request("wp_upload", {"action_num": 16})
    with pytest.raises(LayoutError, match="command_list: at most 16 items"):
        encode_request("wp_upload", {"command_list": [0] * 17})


def test_mission_init_and_download_ack() -> None:
    init = {**c.WP_INIT.example(), "length": 5, "resv": bytes(16)}
    payload = encode_request("wp_init", init)
    assert len(payload) == 51
    assert decode_ack("wp_download_init", b"\x00" + payload).fields == {"ack": 0, **init}
    hp = {**c.HP_SETTING.example(), "reserved": bytes(11)}
    hp_payload = encode_request("hp_upload_start", hp)
    assert decode_ack("hp_download", b"\x00" + hp_payload).fields == {"ack": 0, **hp}
    assert decode_ack("hp_download", b"\x00" + hp_payload + b"\x07").fields == {
        "ack": 0,
        **hp,
        "extra_byte": 7,
    }


# ---------------------------------------------------------------------------------------------- pushes


@pytest.mark.parametrize(
    ("raw", "fields"),
    [
        (bytes([1, 5, 2, 0xE1, 0, 0]), {"mission_type": 1, "target_waypoint": 5, "current_status": 2,
                                         "error_notification": 0xE1, "reserved": 0}),
        (bytes([2, 1, 0x10, 0x27, 3, 25]), {"mission_type": 2, "mission_status": 1, "hp_exec_radius": 10000,
                                             "reason": 3, "hp_exec_vel": 25}),
        (bytes([3, 0, 0, 0, 0, 0]), {"mission_type": 3, "reserved_1": 0, "reserved_2": 0, "reserved_3": 0}),
        (bytes([4, 1, 0x81, 7, 0, 0]), {"mission_type": 4, "last_mission_type": 1, "is_broken": 1,
                                         "reserved_1": 0x40, "reason": 7, "reserved_2": 0, "reserved_3": 0}),
        (bytes([0, 2, 0x00, 0, 0, 0]), {"mission_type": 0, "last_mission_type": 2, "is_broken": 0,
                                         "reserved_1": 0, "reason": 0, "reserved_2": 0, "reserved_3": 0}),
    ],
)  # fmt: skip
def test_status_push_shapes(raw: bytes, fields: dict[str, Any]) -> None:
    msg = decode_request(0x02, 0x03, raw)
    assert (msg.name, msg.fields) == ("status_push", fields)
    assert encode_request("status_push", fields) == raw


@pytest.mark.parametrize(
    ("raw", "fields"),
    [
        (bytes([0, 1, 0x2C, 0x01, 0, 0]), {"incident_type": 0, "is_mission_valid": 1,
                                            "estimated_run_time": 300, "reserved": 0}),
        (bytes([1, 2, 0, 0, 0, 0]), {"incident_type": 1, "repeat": 2, "reserved_1": 0, "reserved_2": 0}),
        (bytes([2, 7, 6, 0, 0, 0]), {"incident_type": 2, "waypoint_index": 7, "current_status": 6,
                                      "reserved_1": 0, "reserved_2": 0, "reserved_3": 0}),
        (bytes([2, 7, 4, 0, 0]), {"incident_type": 2, "waypoint_index": 7, "current_status": 4,
                                   "reserved_1": 0, "reserved_2": 0}),
    ],
)  # fmt: skip
def test_event_push_shapes(raw: bytes, fields: dict[str, Any]) -> None:
    msg = decode_request(0x02, 0x04, raw)
    assert (msg.name, msg.fields) == ("event_push", fields)
    assert encode_request("event_push", fields) == raw


def test_union_errors() -> None:
    with pytest.raises(LayoutError, match="unknown incident_type 3"):
        decode_request(0x02, 0x04, bytes([3, 0, 0, 0, 0, 0]))
    with pytest.raises(LayoutError, match="fits none"):
        decode_request(0x02, 0x03, bytes([1, 0, 0]))
    with pytest.raises(LayoutError, match="mission_type is required"):
        encode_request("status_push", {"target_waypoint": 1})
    assert len(examples_of(c.STATUS_PUSH)) == 5  # waypoint, hotpoint, follow me, atti, IOC
    assert len(examples_of(c.EVENT_PUSH)) == 4  # upload, finish, reached (6 and 5 bytes)


def test_lost_authority_push_and_its_ack() -> None:
    assert encode_request("lost_authority_push") == b"\x04"
    assert encode_ack_payload("lost_authority_push", {"ack": 0}) == b"\x00\x00"


# ---------------------------------------------------------------------------------------------- ack codes


def test_ground_station_ack_codes_from_seed() -> None:
    groups: dict[str, int] = {}
    for group, _ in GS_ACK_CODES.values():
        groups[group] = groups.get(group, 0) + 1
    assert groups == {"common": 29, "follow_me": 3, "hotpoint": 10, "waypoint": 14, "ioc": 2}
    assert GS_ACK_CODES[0xD4] == ("common", "mission not running")
    assert GS_ACK_CODES[0xEA] == ("waypoint", "waypoint task not uploaded")
    assert GS_ACK_CODES[0xA1] == ("ioc", "IOC type error")
    assert GS_ACK_CODES[0xB2] == ("follow_me", "gimbal pitch too large")
    assert c.ack_text(spec_for("hp_set_radius"), 0xC2) == "invalid radius"
    assert c.ack_text(spec_for("hp_set_radius"), 0x01) is None


def test_control_and_activation_ack_texts() -> None:
    assert sorted(c.ACTIVATION_ACK) == list(range(9))
    assert c.ack_text(spec_for("activate"), 7) == "access level too low"
    assert c.ack_text(spec_for("get_version"), 0xFF01) == "not activated"
    assert c.ack_text(spec_for("obtain_control"), 0x0002) == "control obtained"
    assert c.ack_text(spec_for("obtain_control"), 0x00C9) == "IOC mode on"
    assert c.ack_text(spec_for("flight_task"), 5) == "no home point"
    assert c.ack_text(spec_for("flight_task", "m100"), 2) == "started executing"
    assert c.ack_text(spec_for("arm"), 1) == "obtain control first"
    assert c.ack_text(spec_for("set_broadcast_frequency"), 1) == "parameter error"


# ------------------------------------------------------------------------------------ activation, control


def test_activation_defaults() -> None:
    payload = encode_request("activate", {"app_id": 1234567, "fw_version": 0x03030000})
    assert payload == struct.pack("<III", 1234567, 2, 0x03030000) + b"0" * 32
    assert decode_request(0x00, 0x01, payload).fields["bundle_id"] == b"0" * 32


# The A3 reply as DJI's Onboard-SDK 3.x library reads it (Vehicle::parseDroneVersionInfo): u16 ack, the
# ID string and its NUL (at most 16 bytes), the 32-byte name. Bytes written out by hand, not by our encoder.
A3_REPLY = (
    b"\x00\x00"  # ack 0: activated
    + b"0MFDE4B00200YQ\x00"  # ID string, NUL-terminated (15 bytes)
    + b"SDK-v1.1 BETA A3-03.03.100.00\x00\x00\x00"  # 32-byte version name, NUL padded
)
# M100 firmware 2.3: u16 ack, u32 version CRC, 32-byte name (PROTOCOL-NOTES).
M100_23_REPLY = b"\x01\xff" + b"\xef\xbe\xad\xde" + b"SDK-v1.0 BETA M100-02.03.00.00".ljust(32, b"\0")
# Firmware 3.1 (the library's "older than 3.2" branch): u32 CRC, then the ID and its NUL, then the name.
FW31_REPLY = (
    b"\x00\x00" + b"\x04\x03\x02\x01" + b"M100SN\x00" + b"SDK-v1.1 BETA M100-03.01.10.00".ljust(32, b"\0")
)


def test_version_reply_in_each_firmware_layout() -> None:
    a3 = parse_version_reply(*_ack_and_body(A3_REPLY))
    assert (a3.ack, a3.layout, a3.serial, a3.version_crc) == (0, "id", "0MFDE4B00200YQ", None)
    assert (a3.name, a3.hardware, a3.firmware) == ("SDK-v1.1 BETA A3-03.03.100.00", "A3", "03.03.100.00")
    m100 = parse_version_reply(*_ack_and_body(M100_23_REPLY))
    assert (m100.ack, m100.layout, m100.version_crc, m100.hardware) == (0xFF01, "crc", 0xDEADBEEF, "M100")
    old = parse_version_reply(*_ack_and_body(FW31_REPLY))
    assert (old.layout, old.version_crc, old.serial, old.firmware) == (
        "crc_id",
        0x01020304,
        "M100SN",
        "03.01.10.00",
    )
    for raw, layout, kw in (
        (A3_REPLY, "id", {"serial": "0MFDE4B00200YQ"}),
        (M100_23_REPLY, "crc", {"version_crc": 0xDEADBEEF}),
        (FW31_REPLY, "crc_id", {"serial": "M100SN", "version_crc": 0x01020304}),
    ):
        ack, body = _ack_and_body(raw)
        name = parse_version_reply(ack, body).name
        assert encode_version_reply(ack, name, layout=layout, **kw) == raw  # byte-exact both ways
    # through the command table: the body stays raw for the parser
    assert decode_ack("get_version", A3_REPLY).fields == {"ack": 0, "version_data": A3_REPLY[2:]}


# The M100 on firmware 3.1.10.0 (what DJI's Onboard-SDK 3.x accepts): u16 ack, u32 CRC, the ID and its NUL
# (together at most 16 bytes, the library's buffer), the name with the third number a tenth of the real one.
M100_31_REPLY = (
    b"\x00\x00" + b"\xee\x48\x1b\xce" + b"SIMFC00001\x00" + b"SDK-v1.1 BETA M100-03.01.01.00".ljust(32, b"\0")
)


def test_the_m100_3_1_reply_and_what_the_library_cannot_read() -> None:
    m100 = parse_version_reply(*_ack_and_body(M100_31_REPLY))
    assert (m100.layout, m100.version_crc, m100.serial) == ("crc_id", 0xCE1B48EE, "SIMFC00001")
    assert (m100.hardware, m100.firmware) == ("M100", "03.01.01.00")
    kw: dict[str, Any] = {"layout": "crc_id", "serial": "SIMFC00001", "version_crc": 0xCE1B48EE}
    assert encode_version_reply(0, m100.name, **kw) == M100_31_REPLY
    # the library reads CRC + ID up to the first NUL: a zero CRC byte would cut it, a long ID overflow it
    with pytest.raises(ValueError, match="zero byte"):
        encode_version_reply(0, m100.name, layout="crc_id", serial="SIMFC00001", version_crc=0xCE1B00EE)
    with pytest.raises(ValueError, match="longer"):
        encode_version_reply(0, m100.name, layout="crc_id", serial="SIMFC0000001", version_crc=0xCE1B48EE)


def test_a_version_reply_that_fits_no_layout_is_an_error() -> None:
    with pytest.raises(ValueError, match="ID"):
        parse_version_reply(0, b"X" * 40)  # no NUL, no name
    with pytest.raises(ValueError, match="neither"):
        parse_version_reply(0, b"\x01\x02" + b"SDK-v1.1 BETA A3-03.03.100.00".ljust(32, b"\0"))


def _ack_and_body(raw: bytes) -> tuple[int, bytes]:
    return int.from_bytes(raw[:2], "little"), raw[2:]


def test_movement_flag_helpers() -> None:
    assert c.HOVER_FLAG == 0x49 == c.control_flag()
    flag = c.control_flag(c.HORIZONTAL_POSITION, c.VERTICAL_POSITION, c.YAW_ANGLE, c.FRAME_BODY, stable=False)
    assert flag == 0x92
    assert c.split_control_flag(flag) == {
        "horizontal": c.HORIZONTAL_POSITION,
        "vertical": c.VERTICAL_POSITION,
        "yaw": c.YAW_ANGLE,
        "frame": c.FRAME_BODY,
        "stable": 0,
    }
    with pytest.raises(ValueError, match="frame: 0x04"):
        c.control_flag(frame=0x04)
    payload = encode_request("movement_control", {"flag": c.HOVER_FLAG, "x": 1.5, "yaw": -30})
    assert payload == struct.pack("<B4f", 0x49, 1.5, 0.0, 0.0, -30.0)


def test_emergency_brake_is_the_advanced_preset() -> None:
    payload = encode_request("emergency_brake")
    assert payload == b"\x48\x01" + bytes(24)
    assert decode_request(0x01, 0x03, payload).name == "emergency_brake"
    other = encode_request("advanced_movement_control", {"flag": 0x49, "adv_flag": 1, "x": 1.0})
    assert decode_request(0x01, 0x03, other).name == "advanced_movement_control"
    with pytest.raises(LayoutError, match="flag is fixed"):
        encode_request("emergency_brake", {"flag": 0x49})
    with pytest.raises(UnknownCommandError, match="does not exist on firmware 'm100'"):
        spec_for("emergency_brake", "m100")


def test_flight_task_by_firmware() -> None:
    assert encode_request("flight_task", {"command": 1}) == b"\x01"
    assert encode_request("flight_task", {"cmd_sequence": 9, "command": 4}, firmware="m100") == b"\x09\x04"
    assert decode_request(0x01, 0x01, b"\x09\x04", "m100").fields == {"cmd_sequence": 9, "command": 4}
    with pytest.raises(LayoutError, match="fits none of flight_task: 1 bytes"):
        decode_request(0x01, 0x01, b"\x09\x04", "new")
    assert c.FLIGHT_TASKS[1] == "takeoff" and c.FLIGHT_TASKS_M100[4] == "takeoff"


def test_go_home_altitude_write_bytes() -> None:
    # DJI Onboard-SDK 3.9 FlightAssistant::setGoHomeAltitude: 0x01 0x42, u32 hash 952919004 (0x38CC63DC)
    # then the u16 value only; the ACK {u8 ret, u32 hash, u16 value} (GoHomeAltitudeAck), or the value
    # padded to 8 bytes (ParamAckInternal)
    assert encode_request("go_home_altitude_write", {"altitude": 60}) == bytes.fromhex("dc63cc38 3c00")
    assert decode_request(0x01, 0x42, bytes.fromhex("dc63cc38 3c00")).fields == {
        "hash": c.GO_HOME_ALTITUDE_HASH,
        "altitude": 60,
    }
    ack = c.decode_ack("go_home_altitude_write", bytes.fromhex("00 dc63cc38 3c00"))
    assert ack.fields == {"ack": 0, "hash": 952919004, "altitude": 60}
    padded = c.decode_ack("go_home_altitude_write", bytes.fromhex("00 dc63cc38 3c00") + bytes(6))
    assert padded.fields["altitude"] == 60
    with pytest.raises(LayoutError, match="hash is fixed"):
        encode_request("go_home_altitude_write", {"hash": 1, "altitude": 60})
    with pytest.raises(LayoutError):  # another parameter's hash is not this command
        decode_request(0x01, 0x42, bytes.fromhex("01000000 3c00"))
    with pytest.raises(UnknownCommandError, match="does not exist on firmware 'm100'"):
        spec_for("go_home_altitude_write", "m100")


@pytest.mark.parametrize("spec", [s for s in ALL_SPECS if any(f.is_float for f in _fields(s))], ids=_id)
def test_no_float_field_is_written_as_negative_zero(spec: CommandSpec) -> None:
    """-0.0 in (a negated zero stick, a computed velocity at rest) goes out as +0.0: the decoded bytes
    carry no sign bit on a zero."""
    for codec in spec.request:
        if not isinstance(codec, Layout):
            continue
        values = codec.example() | {f.name: -0.0 if f.count == 1 else [-0.0] * f.count for f in codec.fields
                                    if f.is_float}  # fmt: skip
        decoded = codec.decode(codec.encode(values | {k: v for k, v in spec.fixed.items()}))
        for f in codec.fields:
            if f.is_float and f.name not in spec.fixed:
                for v in decoded[f.name] if f.count > 1 else [decoded[f.name]]:
                    assert v == 0.0 and math.copysign(1.0, v) == 1.0, (f.name, v)


def test_go_home_altitude_read_bytes() -> None:
    # DJI Onboard-SDK 3.9 FlightAssistant::getGoHomeAltitude: 0x01 0x41 (parameterRead), the u32 hash alone;
    # the ACK is the write's: {u8 ret, u32 hash, u16 value} or the value padded to 8 bytes
    assert encode_request("go_home_altitude_read") == bytes.fromhex("dc63cc38")
    assert decode_request(0x01, 0x41, bytes.fromhex("dc63cc38")).fields == {"hash": c.GO_HOME_ALTITUDE_HASH}
    ack = c.decode_ack("go_home_altitude_read", bytes.fromhex("00 dc63cc38 1400"))
    assert ack.fields == {"ack": 0, "hash": 952919004, "altitude": 20}
    assert (
        c.decode_ack("go_home_altitude_read", bytes.fromhex("00 dc63cc38 1400") + bytes(6)).fields["altitude"]
        == 20
    )
    with pytest.raises(LayoutError):  # USE_RTK_DATA's hash: another parameter
        decode_request(0x01, 0x41, (1288992843).to_bytes(4, "little"))
    with pytest.raises(UnknownCommandError, match="does not exist on firmware 'm100'"):
        spec_for("go_home_altitude_read", "m100")


def test_kill_switch_layout() -> None:
    payload = encode_request("kill_switch", {"debug_description": b"LINK", "cmd": 1})
    assert payload == b"\0\0LINK" + bytes(6) + b"\x01"
    assert decode_request(0x01, 0x06, payload).fields["cmd"] == 1


def test_lookup_errors_name_the_valid_choices() -> None:
    with pytest.raises(UnknownCommandError, match="valid: get_version, activate"):
        spec_for("take_off")
    with pytest.raises(UnknownCommandError, match="no command 0x09 0x09"):
        decode_request(0x09, 0x09, b"")
    with pytest.raises(LayoutError, match=r"unknown field\(s\) \['spead'\]"):
        encode_request("hp_set_radius", {"spead": 1})
    with pytest.raises(ValueError, match="firmware"):
        spec_for("arm", "a3")


@given(st.integers(0, 3), st.integers(0, 0x40), st.binary(max_size=120))
def test_random_payloads_never_raise_anything_else(cmd_set: int, cmd_id: int, payload: bytes) -> None:
    for firmware in ("new", "m100"):
        with contextlib.suppress(UnknownCommandError, LayoutError):
            decode_request(cmd_set, cmd_id, payload, firmware)


# ---------------------------------------------------------------------------------------------- CLI contract

KEYS = {"protocol", "valid", "seq", "command", "fields", "error", "cmd_set", "cmd_id", "is_ack", "session"}


def test_describe_round_trip_every_command() -> None:
    for spec in ALL_SPECS:
        for firmware in _firmwares(spec):
            codec = spec.request[0]
            for example in examples_of(codec):
                frame = encode_command(
                    spec.cmd_set, spec.cmd_id, codec.encode({**example, **spec.fixed}), 0, 1
                )
                (first,) = describe.decode_bytes(frame, firmware=firmware)
                fields = json.loads(json.dumps(first["fields"]))  # what the CLI hands back in
                raw = describe.encode_command(spec.name, 42, fields, firmware=firmware)
                (d,) = describe.decode_bytes(raw, firmware=firmware)
                assert set(d) >= KEYS
                assert (d["valid"], d["command"], d["seq"], d["error"]) == (True, spec.name, 42, None), d
                assert d["fields"] == fields
                assert decode_frame(raw).payload == decode_frame(frame).payload


def test_describe_matches_acks_to_commands_in_the_stream() -> None:
    cmd = describe.encode_command("hp_set_radius", 7, {"radius": 20})
    ack = describe.encode_command("hp_set_radius", 7, {"ack": 0xC2}, ack=True)
    out = describe.decode_bytes(b"\x00\x01" + cmd + ack)
    assert [d["valid"] for d in out] == [False, True, True]
    assert out[0]["error"] == "garbage" and out[0]["raw"] == "0001"
    assert out[1]["session"] == 2 and out[1]["fields"] == {"radius": 20.0}
    assert out[2] == {
        "protocol": "osdk", "valid": True, "seq": 7, "session": 2, "is_ack": True, "cmd_set": None,
        "cmd_id": None, "command": "hp_set_radius", "fields": {"ack": 0xC2}, "error": None,
        "ack_text": "invalid radius",
    }  # fmt: skip
    lone = describe.decode_bytes(ack)[0]
    assert (lone["command"], lone["fields"], lone["payload"]) == (None, None, "c2")
    assert describe.decode_bytes(ack, ack_command="hp_set_radius")[0]["fields"] == {"ack": 0xC2}


def test_describe_payload_errors_and_unknown_commands() -> None:
    bad = encode_command(0x03, 0x11, bytes(50), 2, 1)
    (d,) = describe.decode_bytes(bad)
    assert (d["valid"], d["command"], d["fields"]) == (True, "wp_upload", None)
    assert "50 bytes" in d["error"] and d["payload"] == "00" * 50
    (u,) = describe.decode_bytes(encode_command(0x0E, 0x00, b"\x01\x02", 3, 1))
    assert (u["valid"], u["command"], u["fields"], u["error"], u["payload"]) == (
        True,
        None,
        None,
        None,
        "0102",
    )
    (e,) = describe.decode_bytes(encode_ack(2, 1, b"\x00\x01\x02"), ack_command="wp_init")
    assert e["command"] == "wp_init" and e["fields"] is None and "ACK of 3 bytes" in e["error"]


def test_describe_encode_hex_bytes_and_errors() -> None:
    raw = describe.encode_command("kill_switch", 1, {"debug_description": "4c494e4b", "cmd": 1})
    assert decode_frame(raw).payload == b"\0\0LINK" + bytes(6) + b"\x01"
    with pytest.raises(ValueError, match="expected a hex string"):
        describe.encode_command("kill_switch", 1, {"debug_description": "LINK"})
    with pytest.raises(ValueError, match="unknown command 'nope'"):
        describe.encode_command("nope", 1, {})
    with pytest.raises(ValueError, match="known:"):
        describe.encode_command("arm", 1, {"armed": 1})
    with pytest.raises(ValueError, match="unknown option"):
        describe.encode_command("arm", 1, {}, speed=3)
    with pytest.raises(ValueError, match="takes no ACK"):
        describe.encode_command("movement_control", 1, {}, ack=True)
    assert decode_frame(describe.encode_command("arm", 1, {"arm": 1}, session=9)).session == 9
    assert decode_frame(describe.encode_command("movement_control", 1, {})).session == 0


def test_describe_flight_data_push_nested_fields() -> None:
    fields = {"bitmap": 0b1000_0000_0010, "quaternion": {"w": 1.0, "x": 0.0, "y": 0.0, "z": 0.0},
              "status": {"flight": 2, "display_mode": 17, "gear": 0, "error": 0}}  # fmt: skip
    raw = describe.encode_command("flight_data_push", 3, fields)
    (d,) = describe.decode_bytes(raw)
    assert d["fields"] == fields
    (m,) = describe.decode_bytes(raw, firmware="m100")  # bit 11 is control_device (2 bytes) there
    assert m["valid"] and m["fields"] is None and m["error"]
