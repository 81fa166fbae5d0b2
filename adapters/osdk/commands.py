"""Onboard SDK command tables: ground station (seed 004: waypoint, hotpoint, follow-me ``0x03``, mission
pushes ``0x02 0x03`` / ``0x02 0x04``), the activation, control and push commands of
PROTOCOL-NOTES ("DJI Onboard SDK" sections) and the data subscription set ``0x0B`` with its push
``0x02 0x05`` (layouts in ``subscription.py``, from DJI's Onboard-SDK 3.9.0), in ONE table keyed by
``(cmd_set, cmd_id)``.

Each key maps to one or more :class:`CommandSpec` (more than one only where the wire shares an id:
``0x01 0x03`` carries the 17-byte movement control, the 26-byte advanced form and its emergency-brake
preset; ``0x01 0x01`` and ``0x02 0x00`` differ by firmware). A spec names its request and ACK
layouts (packed, little-endian; ``#pragma pack(1)`` in DJI's headers), the ACK code texts, the
session it is sent on, its retry timing, units (in the layout fields), direction and source section.
Encoders, decoders, the CLI and the test matrix derive from the table: no ladders over ids.

ACK frames carry no CmdSet/CmdID: the caller matches an ACK to its command by ``(session, seq)``
(:class:`adapters.osdk.protocol.SessionTable`) and then decodes it with :func:`decode_ack`.

Where the seed disagrees with PROTOCOL-NOTES, the notes (real devices) win; each choice is written
next to the layout it shapes. Seed typos in names are fixed with a comment.

Owns: payload layouts and their lookup. Must not know frames, links or clocks (sans-I/O).

Why this module is longer than 500 lines: it is a declarative table: one entry per command of seed 004
and of DJI's control and telemetry sets, each naming its layouts, fields, units and delivery, plus the ACK
code texts the seed lists; its length is the protocol's.
"""

from __future__ import annotations

import types
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from adapters.errors import UnknownCommandError
from adapters.osdk.protocol import SessionMode
from adapters.osdk.subscription import ADD_PACKAGE, PACKAGE_DATA, PACKAGE_ID, RESET, SUBSCRIBE_ACK, VERIFY
from adapters.osdk.telemetry import FIRMWARES, FlightDataCodec, check_firmware, examples_of
from adapters.wire.bits import BitLayout, Bits
from adapters.wire.layout import Field, Layout, LayoutError, PayloadCodec, Tail
from adapters.wire.table import EMPTY, CommandSpec, Delivery, Message, Table, TaggedUnion, sizes_text

__all__ = [
    "ACTIVATION_ACK",
    "ARM_ACK",
    "BY_NAME",
    "COMMAND_NAMES",
    "COMMAND_TABLE",
    "CONTROL_ACK",
    "EMERGENCY_BRAKE_FLAG",
    "FIRMWARE_CODES",
    "FLIGHT_TASKS",
    "FLIGHT_TASKS_M100",
    "FLIGHT_TASK_ACK",
    "FLIGHT_TASK_M100_ACK",
    "FREQUENCY_ACK",
    "FROM_FC",
    "GS_ACK_CODES",
    "GS_ACK_TEXT",
    "HOVER_FLAG",
    "TABLE",
    "TO_FC",
    "VERSION_ACK",
    "CommandSpec",
    "DroneVersion",
    "FirmwareCodes",
    "Message",
    "TaggedUnion",
    "ack_text",
    "control_flag",
    "decode_ack",
    "decode_request",
    "encode_ack_payload",
    "encode_request",
    "encode_version_reply",
    "examples_of",
    "parse_version_reply",
    "spec_for",
    "specs_at",
    "split_control_flag",
]

TO_FC = "to_fc"  # onboard computer -> flight controller
FROM_FC = "from_fc"  # flight controller -> onboard computer (pushes)

# --------------------------------------------------------------------------------------------------
# ACK code texts

# Seed 004 "ACK Code": every ground-station code, code -> (group, text). The groups never overlap.
GS_ACK_CODES: dict[int, tuple[str, str]] = {
    # Common ACK
    0x00: ("common", "success"),
    0xD0: ("common", "mode bar not in F"),
    0xD1: ("common", "not in Navi mode"),
    0xD2: ("common", "IOC enabled"),
    0xD3: ("common", "mission not init"),
    0xD4: ("common", "mission not running"),  # seed: "missino"
    0xD5: ("common", "mission running"),
    0xD6: ("common", "flight duration not satisfied"),
    0xD7: ("common", "mission with higher priority is running"),
    0xD8: ("common", "GPS health not satisfied"),
    0xD9: ("common", "low battery"),
    0xDA: ("common", "drone not in air when init"),
    0xDB: ("common", "invalid mission parameter"),  # seed: "missino"
    0xDC: ("common", "execution condition not satisfied"),
    0xDD: ("common", "mission will fly through no-fly zone"),
    0xDE: ("common", "HOME point not recorded"),
    0xDF: ("common", "drone in no-fly zone"),
    0xC0: ("common", "altitude higher than max"),
    0xC1: ("common", "altitude lower than min"),
    0xC7: ("common", "too far"),
    0xC8: ("common", "drone does not support ground station functions"),
    0xC9: ("common", "too far from the hotpoint/first waypoint"),
    0xCA: ("common", "drone in beginner mode"),
    0xF0: ("common", "drone is taking off"),
    0xF1: ("common", "drone is landing"),
    0xF2: ("common", "drone is going back home"),
    0xF3: ("common", "drone is arming"),
    0xF4: ("common", "invalid command"),
    0xFF: ("common", "unknown command"),  # seed's cell ends in a broken "</th>"
    # Follow me ACK
    0xB0: ("follow_me", "drone too far from mobile"),
    0xB1: ("follow_me", "disconnect time too long"),
    0xB2: ("follow_me", "gimbal pitch too large"),
    # Hotpoint ACK
    0xC2: ("hotpoint", "invalid radius"),
    0xC3: ("hotpoint", "velocity too large"),
    0xC4: ("hotpoint", "invalid start point"),
    0xC5: ("hotpoint", "invalid yaw mode"),
    0xC6: ("hotpoint", "too far to go back to route"),
    0xA2: ("hotpoint", "invalid float number"),
    0xA3: ("hotpoint", "invalid latitude/longitude"),  # seed: "laittude"
    0xA6: ("hotpoint", "invalid direction"),
    0xA9: ("hotpoint", "hotpoint already paused"),
    0xAA: ("hotpoint", "hotpoint not paused"),
    # Waypoint ACK
    0xE0: ("waypoint", "invalid mission data"),
    0xE1: ("waypoint", "invalid waypoint data"),
    0xE2: ("waypoint", "planned route too long"),
    0xE3: ("waypoint", "flight route too long"),
    0xE4: ("waypoint", "index larger than max number"),
    0xE5: ("waypoint", "neighbor waypoints too close"),
    0xE6: ("waypoint", "neighbor waypoints too far"),
    0xE7: ("waypoint", "damping check failed"),
    0xE8: ("waypoint", "invalid action parameter"),
    0xE9: ("waypoint", "waypoint upload not finished"),
    0xEA: ("waypoint", "waypoint task not uploaded"),
    0xEB: ("waypoint", "not all waypoints uploaded"),
    0xEC: ("waypoint", "request is running"),
    0xED: ("waypoint", "cannot pause: not running"),
    # IOC ACK
    0xA0: ("ioc", "too close to HOME point"),
    0xA1: ("ioc", "IOC type error"),
}
GS_ACK_TEXT: dict[int, str] = {code: text for code, (_, text) in GS_ACK_CODES.items()}

# PROTOCOL-NOTES "Activation and version" (u16 ACKs).
ACTIVATION_ACK: dict[int, str] = {
    0x0000: "success",
    0x0001: "invalid parameters",
    0x0002: "encrypted packet not recognised",
    0x0003: "new app ID, attempting to activate",
    0x0004: "no response from the DJI app",
    0x0005: "DJI app has no internet",
    0x0006: "server refused activation",
    0x0007: "access level too low",
    0x0008: "wrong SDK version",
}
VERSION_ACK: dict[int, str] = {0x0000: "activated", 0xFF01: "not activated"}
FREQUENCY_ACK: dict[int, str] = {0x0000: "success", 0x0001: "parameter error"}
# PROTOCOL-NOTES 0x01 0x00; 3/4 mean "send again with a new seq".
CONTROL_ACK: dict[int, str] = {
    0x0000: "RC mode switch not in F",
    0x0001: "control released",
    0x0002: "control obtained",
    0x0003: "obtain in progress",
    0x0004: "release in progress",
    0x0005: "RC must be in P mode",
    0x0006: "RC must be in F mode",
    0x00C9: "IOC mode on",
}
FLIGHT_TASKS: dict[int, str] = {
    1: "takeoff",
    2: "landing",
    6: "go_home",
    7: "start_motors",
    8: "stop_motors",
    12: "exit_go_home",
    13: "exit_takeoff",
    14: "exit_landing",
}
FLIGHT_TASK_ACK: dict[int, str] = {
    0: "success",
    1: "motors on",
    2: "motors off",
    3: "in air",
    4: "not in air",
    5: "no home point",
    6: "bad GPS",
    7: "in simulator mode",
    8: "already running",
    9: "not running",
    10: "invalid command",
}
FLIGHT_TASKS_M100: dict[int, str] = {1: "go_home", 4: "takeoff", 6: "landing"}
FLIGHT_TASK_M100_ACK: dict[int, str] = {0x0001: "execution failed", 0x0002: "started executing"}


@dataclass(frozen=True, slots=True)
class FirmwareCodes:
    """What differs between the two flight-controller generations for the same intent: one row per
    firmware, so the adapter says "take off" and never a number (seed 004; PROTOCOL-NOTES)."""

    tasks: Mapping[str, int]  # intent -> 0x01 0x01 command code
    task_ok: int  # the 0x01 0x01 ACK that means the task started
    task_ack: Mapping[int, str]
    in_air: frozenset[int]  # 0x02 0x00 status.flight values in the air
    on_ground: frozenset[int]
    emergency_brake: bool  # the 26-byte brake (0x01 0x03 advanced) exists


FIRMWARE_CODES: dict[str, FirmwareCodes] = {
    # A3/N3/M600/M210 (OSDK 3.x): flight status 0 stopped, 1 on ground, 2 in air
    "new": FirmwareCodes(
        tasks={"takeoff": 1, "landing": 2, "go_home": 6, "exit_go_home": 12, "exit_landing": 14},
        task_ok=0,
        task_ack=FLIGHT_TASK_ACK,
        in_air=frozenset({2}),
        on_ground=frozenset({0, 1}),
        emergency_brake=True,
    ),
    # M100 legacy firmware: tasks 1 go home, 4 take off, 6 landing, ACK 0x0002 = started; flight status
    # 1 standby, 2 taking off, 3 in air, 4 landing, 5 landed
    "m100": FirmwareCodes(
        tasks={"takeoff": 4, "landing": 6, "go_home": 1},
        task_ok=0x0002,
        task_ack=FLIGHT_TASK_M100_ACK,
        in_air=frozenset({3}),
        on_ground=frozenset({1, 5}),
        emergency_brake=False,
    ),
}
ARM_ACK: dict[int, str] = {0: "success", 1: "obtain control first", 2: "already in that state", 3: "in air"}
LOST_AUTHORITY_ACK: dict[int, str] = {0x0000: "received"}

# Value meanings, for documentation and the adapter.
MISSION_TYPES: dict[int, str] = {0: "atti", 1: "waypoint", 2: "hotpoint", 3: "follow_me", 4: "ioc"}
INCIDENT_TYPES: dict[int, str] = {0: "upload_finish", 1: "mission_finish", 2: "reach_point"}
WP_ACTIONS: dict[int, str] = {
    0: "stay",
    1: "simple_shot",
    2: "video_start",
    3: "video_stop",
    4: "craft_yaw",
    5: "gimbal_pitch",
}
FREQUENCIES: dict[int, str] = {0: "off", 1: "1 Hz", 2: "10 Hz", 3: "50 Hz", 4: "100 Hz", 5: "keep"}

# --------------------------------------------------------------------------------------------------
# Movement control flag (0x01 0x03 byte 0; PROTOCOL-NOTES, OSDK Control::*Logic)

HORIZONTAL_ANGLE = 0x00  # tilt angle, deg
HORIZONTAL_VELOCITY = 0x40  # m/s
HORIZONTAL_POSITION = 0x80  # position offset, m
HORIZONTAL_ANGULAR_RATE = 0xC0  # OSDK only (new FW), deg/s; not in the notes
VERTICAL_VELOCITY = 0x00  # m/s, +-5
VERTICAL_POSITION = 0x10  # height, m
VERTICAL_THRUST = 0x20  # %
YAW_ANGLE = 0x00  # deg
YAW_RATE = 0x08  # deg/s, +-150
FRAME_GROUND = 0x00  # North-East-Up
FRAME_BODY = 0x02  # Forward-Right
STABLE = 0x01  # brake and hover when the input is zero
HORIZONTAL_MASK, VERTICAL_MASK, YAW_MASK, FRAME_MASK, STABLE_MASK = 0xC0, 0x30, 0x08, 0x06, 0x01

_FLAG_PARTS: dict[str, tuple[int, tuple[int, ...]]] = {
    "horizontal": (
        HORIZONTAL_MASK,
        (HORIZONTAL_ANGLE, HORIZONTAL_VELOCITY, HORIZONTAL_POSITION, HORIZONTAL_ANGULAR_RATE),
    ),
    "vertical": (VERTICAL_MASK, (VERTICAL_VELOCITY, VERTICAL_POSITION, VERTICAL_THRUST)),
    "yaw": (YAW_MASK, (YAW_ANGLE, YAW_RATE)),
    "frame": (FRAME_MASK, (FRAME_GROUND, FRAME_BODY)),
    "stable": (STABLE_MASK, (0, STABLE)),
}


def control_flag(
    horizontal: int = HORIZONTAL_VELOCITY,
    vertical: int = VERTICAL_VELOCITY,
    yaw: int = YAW_RATE,
    frame: int = FRAME_GROUND,
    stable: bool = True,
) -> int:
    """The movement-control flag byte from its named parts (each one of the constants above)."""
    parts = {"horizontal": horizontal, "vertical": vertical, "yaw": yaw, "frame": frame}
    parts["stable"] = STABLE if stable else 0
    flag = 0
    for name, value in parts.items():
        _, allowed = _FLAG_PARTS[name]
        if value not in allowed:
            raise ValueError(f"{name}: 0x{value:02X} is not one of {[f'0x{a:02X}' for a in allowed]}")
        flag |= value
    return flag


def split_control_flag(flag: int) -> dict[str, int]:
    """The flag byte's parts (masked values, comparable with the constants above)."""
    return {name: flag & mask for name, (mask, _) in _FLAG_PARTS.items()}


# Zero velocity with the stable bit: what the gateway's watchdog streams to hover (PROTOCOL-NOTES).
HOVER_FLAG = control_flag(HORIZONTAL_VELOCITY, VERTICAL_VELOCITY, YAW_RATE, FRAME_GROUND, stable=True)
# OSDK Control::emergencyBrake sends AdvancedCtrlData(72, ...) with advFlag 0x01: flag 0x48 =
# horizontal velocity | yaw rate (the header comment says 75; the SDK sends 72 = 0x48).
EMERGENCY_BRAKE_FLAG = 0x48


# Union payloads (one struct size, shape chosen by the first byte) are adapters.wire.table.TaggedUnion
# without a head: the tag is the first byte of every shape.


# --------------------------------------------------------------------------------------------------
# Layouts


def _f(name: str, code: str, unit: str = "", doc: str = "", count: int = 1) -> Field:
    return Field(name, code, count=count, unit=unit, doc=doc)


U8_ACK = Layout((_f("ack", "B", "", "ACK code"),))
U16_ACK = Layout((_f("ack", "H", "", "ACK code"),))
ARBITRARY = Layout((_f("arbitrary", "B", "", "any value (seed: 'uint8_t with arbitrary value')"),))
_ACK = _f("ack", "B", "", "ground-station ACK code")

# 0x03 0x10 waypoint_mission_info_comm_t, packed: u8 (1) + 2 f32 (8) + 6 u8 (6) + 2 f64 (16) + f32 (4)
# + resv[16] (16) = 51 bytes (PROTOCOL-NOTES: 51).
WP_INIT_FIELDS = (
    _f("length", "B", "", "count of waypoints"),
    _f("vel_cmd_range", "f", "m/s", "maximum joystick speed, 2..15"),
    _f("idle_vel", "f", "m/s", "cruising speed without joystick input, <= vel_cmd_range"),
    _f("action_on_finish", "B", "", "0 none, 1 go home, 2 land, 3 back to point 0, 4 infinite"),
    _f("mission_exec_num", "B", "", "1 once, 2 twice"),
    _f("yaw_mode", "B", "", "0 auto, 1 lock initial, 2 RC, 3 waypoint tgt_yaw"),
    _f("trace_mode", "B", "", "0 point to point, 1 coordinated turn"),
    _f("action_on_rc_lost", "B", "", "0 exit and failsafe, 1 continue"),
    _f("gimbal_pitch_mode", "B", "", "0 free, 1 auto"),
    _f("hp_lati", "d", "rad", "focus latitude"),
    _f("hp_longti", "d", "rad", "focus longitude"),
    _f("hp_alti", "f", "m", "focus altitude relative to takeoff"),
    _f("resv", "s", "", "reserved, must be 0", count=16),
)
WP_INIT = Layout(WP_INIT_FIELDS)


def _waypoint_fields(slots: int) -> tuple[Field, ...]:
    return (
        _f("index", "B", "", "waypoint index (OSDK WayPointSettings.index; not in the seed struct)"),
        _f("latitude", "d", "rad"),
        _f("longitude", "d", "rad"),
        _f("altitude", "f", "m", "relative to takeoff"),
        _f("damping_dis", "f", "m", "bend length (coordinated turn only)"),
        _f("tgt_yaw", "h", "deg"),
        _f("tgt_gimbal_pitch", "h", "deg"),
        _f("turn_mode", "B", "", "0 clockwise, 1 counter-clockwise"),
        _f("resv", "s", "", "reserved", count=8),
        _f("has_action", "B", "", "0 no action, 1 has action"),
        _f("action_time_limit", "H", "s"),
        _f("action", "B", "", "action_num : 4 | action_rpt : 4"),
        _f("command_list", "B", "", "WP_ACTIONS values", count=slots),
        _f("command_param", "h", "", "per action: ms, deg, ...", count=slots),
    )


_WP_ACTION_BITS = (Bits("action", (("action_num", 4), ("action_rpt", 4))),)
# 0x03 0x11 waypoint. The seed's waypoint_comm_t, packed, is lat 8 + lon 8 + altitude 4 + damping_dis 4
# + tgt_yaw 2 + tgt_gimbal_pitch 2 + turn_mode 1 + resv 8 + has_action 1 + action_time_limit 2 = 40,
# plus waypoint_action_comm_t = action_num/rpt 1 + command_list[15] 15 + command_param[15] 30 = 46:
# 86 bytes, with no index. DJI's OSDK (WayPointSettings) sends a leading u8 index and 16-slot arrays:
# 1 + 40 + 1 + 16 + 32 = 90 (PROTOCOL-NOTES: encode 90). The seed's ACK {ack, index, waypoint_comm_t}
# shows the other shape on the wire: index + the 86-byte struct = 87. Decode 90 or 87, encode 90.
WAYPOINT = BitLayout(_waypoint_fields(16), _WP_ACTION_BITS)
WAYPOINT_SEED = BitLayout(_waypoint_fields(15), _WP_ACTION_BITS)

# 0x03 0x20 hotpoint_mission_setting_t: u8 + 4 f64 (32) + f32 (4) + 3 u8 + reserved[11] = 51 bytes.
HP_SETTING_FIELDS = (
    _f("version", "B", "", "reserved, 0"),
    _f("hp_latitude", "d", "rad"),
    _f("hp_longitude", "d", "rad"),
    _f("hp_altitude", "d", "m", "relative to takeoff"),
    _f("hp_radius", "d", "m", "5..500"),
    _f("angle_rate", "f", "deg/s", "0..30"),
    _f("is_clockwise", "B", "", "0 counter-clockwise, 1 clockwise"),
    _f("start_point_position", "B", "", "0 north, 1 south, 2 west, 3 east, 4 nearest"),
    _f("yaw_mode", "B", "", "0 velocity direction, 1 inside, 2 outside, 3 RC, 4 starting yaw"),
    _f("reserved", "s", "", "reserved", count=11),
)
HP_SETTING = Layout(HP_SETTING_FIELDS)
# 0x03 0x30 follow_me_mission_setting_t: 2 u8 + 2 f64 + 2 u16 + u8 = 23 bytes.
FM_SETTING = Layout(
    (
        _f("follow_mode", "B", "", "reserved, 0"),
        _f("yaw_mode", "B", "", "1 point to target, 0 RC"),
        _f("init_latitude", "d", "rad"),
        _f("init_longitude", "d", "rad"),
        _f("init_alti", "H", "m"),
        _f("init_mag_angle", "H", "", "reserved"),
        _f("follow_sensitivity", "B", "", "reserved, 0"),
    )
)
# 0x03 0x33 cmd_mission_follow_target_info: 2 f64 + 2 u16 = 20 bytes.
FM_TARGET = Layout(
    (
        _f("latitude", "d", "rad"),
        _f("longitude", "d", "rad"),
        _f("altitude", "H", "m"),
        _f("mag_angle", "H", "", "reserved"),
    )
)

# 0x02 0x03 mission status push: four 6-byte shapes chosen by mission_type.
_ST_WAYPOINT = Layout(
    (
        _f("mission_type", "B", "", "1 waypoint"),
        _f("target_waypoint", "B"),
        _f("current_status", "B"),
        _f("error_notification", "B"),
        _f("reserved", "H"),
    )
)
_ST_HOTPOINT = Layout(
    (
        _f("mission_type", "B", "", "2 hotpoint"),
        _f("mission_status", "B", "", "0 init, 1 running, 2 paused"),
        _f("hp_exec_radius", "H", "cm", "distance to the hotpoint"),
        _f("reason", "B"),
        _f("hp_exec_vel", "B", "0.1 deg/s", "angular velocity in ground frame"),
    )
)
_ST_FOLLOW_ME = Layout(
    (
        _f("mission_type", "B", "", "3 follow me"),
        _f("reserved_1", "B"),
        _f("reserved_2", "H"),
        _f("reserved_3", "H"),
    )
)
_ST_DEFAULT = BitLayout(
    (
        _f("mission_type", "B", "", "0 atti, 4 IOC"),
        _f("last_mission_type", "B"),
        _f("flags", "B", "", "is_broken : 1 | reserved_1 : 7"),
        _f("reason", "B"),
        _f("reserved_2", "B"),
        _f("reserved_3", "B"),
    ),
    (Bits("flags", (("is_broken", 1), ("reserved_1", 7))),),
)
STATUS_PUSH = TaggedUnion(
    "mission_type",
    {1: (_ST_WAYPOINT,), 2: (_ST_HOTPOINT,), 3: (_ST_FOLLOW_ME,)},
    default=(_ST_DEFAULT,),
    default_keys=(0, 4),
)

# 0x02 0x04 waypoint event push, chosen by incident_type. The seed says the three shapes have the same
# size, yet its reach-point struct adds up to 5 bytes against 6 for the others (OSDK's
# WayPointReachedData is 5 too). We decode 5 or 6 (a trailing reserved byte) and encode 6, the size the
# seed says the FC uses for all three.
_EV_UPLOAD = Layout(
    (
        _f("incident_type", "B", "", "0 upload finished"),
        _f("is_mission_valid", "B"),
        _f("estimated_run_time", "H", "s"),
        _f("reserved", "H"),
    )
)
_EV_FINISH = Layout(
    (
        _f("incident_type", "B", "", "1 mission finished"),
        _f("repeat", "B"),
        _f("reserved_1", "H"),
        _f("reserved_2", "H"),
    )
)
_EV_REACHED_FIELDS = (
    _f("incident_type", "B", "", "2 waypoint reached"),
    _f("waypoint_index", "B"),
    _f("current_status", "B", "", "4 pre-action, 6 post-action (OSDK)"),
    _f("reserved_1", "B"),
    _f("reserved_2", "B"),
)
_EV_REACHED_6 = Layout((*_EV_REACHED_FIELDS, _f("reserved_3", "B", "", "padding to the common 6 bytes")))
_EV_REACHED_5 = Layout(_EV_REACHED_FIELDS)
EVENT_PUSH = TaggedUnion(
    "incident_type", {0: (_EV_UPLOAD,), 1: (_EV_FINISH,), 2: (_EV_REACHED_6, _EV_REACHED_5)}
)

# Activation set 0x00 (PROTOCOL-NOTES "Activation and version").
ACTIVATE = Layout(
    (
        _f("app_id", "I"),
        _f("api_level", "I", "", "2"),
        _f("fw_version", "I", "", "the SDK's firmware version word"),
        _f("bundle_id", "s", "", "32 x ASCII '0'", count=32),
    )
)
# The 0x00 0x00 reply: u16 ack, then a body whose layout depends on the firmware (PROTOCOL-NOTES
# "Activation and version", corrected against DJI's Onboard-SDK 3.x parser, Vehicle::parseDroneVersionInfo):
#   A3/N3/M600/M210 (firmware >= 3.2): ID string, NUL-terminated, <= 16 bytes with the NUL; 32-byte name
#   firmware 3.1 (M100 3.1, old A3):   u32 version CRC, then the ID string and its NUL; 32-byte name
#   M100 2.3:                          u32 version CRC; 32-byte name
# The name reads "SDK-v1.1 BETA A3-03.03.100.00": the hardware after the second space up to '-', the
# firmware version after it. The body is kept raw here and read by parse_version_reply / made by
# encode_version_reply, because its ID field has no fixed length.
# The library copies the CRC and the ID together into one 16-byte buffer, up to the first NUL (at most 16
# bytes after the ack), and only then splits off the CRC when the firmware is older than 3.2: so in the
# 3.1 layout the CRC bytes are never 0 and CRC + ID + NUL fit in 16 bytes (an ID of at most 11
# characters; the 3.1-era library, Onboard-SDK 3.1.9 CoreAPI::getDroneVersion, reads an 11-byte ID).
# An M100 on the firmware 3.x supports (3.1.10.0, Version::M100_31) writes its third number a tenth of
# the real one: "M100-03.01.01.00"; the library multiplies it by 10 for hardware "M100". The names are
# reported as sent (DroneVersion.firmware).
VERSION_REPLY = Layout(
    (_f("ack", "H", "", "0 activated, 0xFF01 not activated"),),
    tail=Tail("version_data", "firmware-specific: [u32 CRC] [ID NUL] 32-byte version name"),
)
VERSION_NAME_BYTES = 32
VERSION_ID_MAX = 16  # with its NUL


@dataclass(frozen=True, slots=True)
class DroneVersion:
    """A decoded 0x00 0x00 reply. ``layout``: ``id`` (firmware >= 3.2), ``crc_id`` (3.1) or ``crc``
    (M100 2.3); ``hardware``/``firmware`` are read from ``name`` (None when it does not follow the form)."""

    ack: int
    layout: str
    name: str
    serial: str | None = None
    version_crc: int | None = None
    hardware: str | None = None
    firmware: str | None = None


def _name_parts(name: str) -> tuple[str | None, str | None]:
    parts = name.split(" ")
    if len(parts) < 3 or "-" not in parts[2]:
        return None, None
    hardware, _, firmware = parts[2].partition("-")
    return (hardware or None), (firmware or None)


def parse_version_reply(ack: int, body: bytes) -> DroneVersion:
    """Read the body of a 0x00 0x00 reply in any of the three layouts. Raises ``ValueError`` when it is
    none of them (too short, no NUL where the ID must end)."""
    name_at = body.find(b"SDK-")
    if name_at < 0 or len(body) < name_at + 4:
        # no recognisable name: the library's rule (ID up to NUL, then the name) decides the split
        nul = body.find(b"\0", 0, VERSION_ID_MAX)
        if nul < 0 or len(body) < nul + 1 + 1:
            raise ValueError(f"version reply of {len(body)} bytes has no ID string and no version name")
        name_at = nul + 1
    prefix, raw_name = body[:name_at], body[name_at : name_at + VERSION_NAME_BYTES]
    name = raw_name.split(b"\0", 1)[0].decode("ascii", errors="replace")
    hardware, firmware = _name_parts(name)
    if prefix.endswith(b"\0"):
        ident = prefix[:-1]
        if firmware is not None and _fw_tuple(firmware) < (3, 2) and len(ident) >= 4:
            crc = int.from_bytes(ident[:4], "little")
            serial = ident[4:].decode("ascii", errors="replace")
            return DroneVersion(ack, "crc_id", name, serial or None, crc, hardware, firmware)
        if len(prefix) > VERSION_ID_MAX:
            raise ValueError(f"version reply ID string of {len(prefix)} bytes (at most {VERSION_ID_MAX})")
        serial = ident.decode("ascii", errors="replace")
        return DroneVersion(ack, "id", name, serial or None, None, hardware, firmware)
    if len(prefix) == 4:
        return DroneVersion(ack, "crc", name, None, int.from_bytes(prefix, "little"), hardware, firmware)
    raise ValueError(f"version reply: {len(prefix)} bytes before the name are neither a CRC nor an ID")


def _fw_tuple(firmware: str) -> tuple[int, ...]:
    try:
        return tuple(int(p) for p in firmware.split("."))
    except ValueError:
        return (99,)


def encode_version_reply(
    ack: int, name: str, *, layout: str = "id", serial: str = "", version_crc: int = 0
) -> bytes:
    """The bytes of a 0x00 0x00 reply (ack included) in ``layout`` (see :class:`DroneVersion`)."""
    raw_name = name.encode("ascii")[:VERSION_NAME_BYTES].ljust(VERSION_NAME_BYTES, b"\0")
    head = ack.to_bytes(2, "little")
    ident = serial.encode("ascii")
    if layout == "id":
        if len(ident) + 1 > VERSION_ID_MAX:
            raise ValueError(f"ID {serial!r} longer than {VERSION_ID_MAX - 1} characters")
        return head + ident + b"\0" + raw_name
    crc = (version_crc & 0xFFFFFFFF).to_bytes(4, "little")
    if layout == "crc_id":
        if 0 in crc:
            raise ValueError(f"version CRC 0x{version_crc:08X} has a zero byte: it would end the ID early")
        if len(crc) + len(ident) + 1 > VERSION_ID_MAX:
            raise ValueError(f"ID {serial!r} longer than {VERSION_ID_MAX - 5} characters after the CRC")
        return head + crc + ident + b"\0" + raw_name
    if layout == "crc":
        return head + crc + raw_name
    raise ValueError(f"unknown version reply layout {layout!r}")


BROADCAST_FREQUENCY = Layout((_f("frequency", "B", "", "rate code per item: FREQUENCIES", count=16),))

# Control set 0x01 (PROTOCOL-NOTES "control (0x01)").
OBTAIN_CONTROL = Layout((_f("control", "B", "", "1 obtain, 0 release"),))
FLIGHT_TASK = Layout((_f("command", "B", "", "FLIGHT_TASKS"),))
FLIGHT_TASK_M100 = Layout((_f("cmd_sequence", "B"), _f("command", "B", "", "FLIGHT_TASKS_M100")))
MOVEMENT = Layout(
    (
        _f("flag", "B", "", "control_flag(): horizontal | vertical | yaw | frame | stable"),
        _f("x", "f", "", "roll/x: deg, m/s or m by flag"),
        _f("y", "f", "", "pitch/y"),
        _f("z", "f", "", "vertical: m/s, m or % by flag"),
        _f("yaw", "f", "", "deg or deg/s by flag"),
    )
)
# OSDK AdvancedCtrlData: u8 flag, u8 advFlag, 6 x f32 = 26 bytes.
ADVANCED_MOVEMENT = Layout(
    (
        _f("flag", "B"),
        _f("adv_flag", "B", "", "bit 0 feed-forward on, bit 6 brake, ..."),
        _f("x", "f"),
        _f("y", "f"),
        _f("z", "f"),
        _f("yaw", "f"),
        _f("x_feedforward", "f", "m/s^2"),
        _f("y_feedforward", "f", "m/s^2"),
    )
)
EMERGENCY_BRAKE_VALUES: Mapping[str, Any] = types.MappingProxyType(
    {"flag": EMERGENCY_BRAKE_FLAG, "adv_flag": 0x01, "x": 0.0, "y": 0.0, "z": 0.0, "yaw": 0.0}
    | {"x_feedforward": 0.0, "y_feedforward": 0.0}
)
ARM = Layout((_f("arm", "B", "", "1 arm, 0 disarm"),))
# 0x01 0x06 kill switch, 13 bytes per PROTOCOL-NOTES. Layout from OSDK's KillSwitchData header:
# u8 high_version, u8 low_version, u8 debug_description[10], u8 {cmd : 2, reserved : 6}
# (cmd: 0 no action, 1 enable = stop motors, 2 disable). The version bytes OSDK fills in were not
# confirmed: the caller supplies them (default 0), and the ACK code texts are unknown (u16 assumed,
# like the rest of the control set).
KILL_SWITCH = BitLayout(
    (
        _f("high_version", "B", "", "FW version match (value not confirmed)"),
        _f("low_version", "B", "", "protocol compatibility (value not confirmed)"),
        _f("debug_description", "s", "", "reason, logged by the FC", count=10),
        _f("cmd_byte", "B", "", "cmd : 2 | reserved : 6"),
    ),
    (Bits("cmd_byte", (("cmd", 2), ("reserved", 6))),),
)
LOST_AUTHORITY = Layout((_f("reason", "B", "", "4: RC or mobile app took over"),))

# 0x01 0x42 parameter write by hash (DJI Onboard-SDK 3.9+ FlightAssistant::writeParameterByHash; M210 V2
# and later firmware; no M100 equivalent): u32 hash, then only the value's own bytes (OSDK sends
# ``sizeof(hash) + len``). The FC answers u8 ret code (0 = written), the hash and the value it now holds
# (OSDK's GoHomeAltitudeAck, 7 bytes; its generic ParamAckInternal pads the value to 8 bytes, 13 in all).
# OSDK refuses a go-home altitude outside MIN_GO_HOME_HEIGHT..MAX_FLIGHT_HEIGHT = 20..500 m before sending.
GO_HOME_ALTITUDE_HASH = 952919004  # FlightAssistant::ParamHashValue::GO_HOME_ALTITUDE
GO_HOME_ALTITUDE_RANGE = (20, 500)  # m above the take-off point
PARAM_ACK: dict[int, str] = {0: "written"}
GO_HOME_ALTITUDE_WRITE = Layout(
    (_f("hash", "I", "", "GO_HOME_ALTITUDE_HASH"), _f("altitude", "H", "m", "go-home altitude, 20..500"))
)
# 0x01 0x41 parameter read by hash (FlightAssistant::readParameterByHash, getGoHomeAltitude): u32 hash only;
# the ACK is the write's (u8 ret code, the hash, the value held). OSDK's sync read wants the hash echoed and
# at most 13 bytes, its async decoder at least the 7 of GoHomeAltitudeAck.
GO_HOME_ALTITUDE_READ = Layout((_f("hash", "I", "", "GO_HOME_ALTITUDE_HASH"),))
_GO_HOME_ACK_FIELDS = (_f("ack", "B", "", "0 written"), _f("hash", "I"), _f("altitude", "H", "m"))
GO_HOME_ALTITUDE_ACKS = (
    Layout(_GO_HOME_ACK_FIELDS),
    Layout((*_GO_HOME_ACK_FIELDS, _f("pad", "s", "", "rest of the 8-byte value", count=6))),
)


# --------------------------------------------------------------------------------------------------
# The table


def _spec(
    name: str,
    cmd_set: int,
    cmd_id: int,
    request: tuple[PayloadCodec, ...],
    ack: tuple[PayloadCodec, ...] = (),
    ack_codes: Mapping[int, str] = EMPTY,
    *,
    direction: str = TO_FC,
    session: SessionMode = SessionMode.ACK_REQUIRED,
    timeout: float = 0.5,
    retries: int = 2,
    firmware: str | None = None,
    defaults: Mapping[str, Any] = EMPTY,
    fixed: Mapping[str, Any] = EMPTY,
    section: str = "",
    doc: str = "",
    handler: str = "",
) -> CommandSpec:
    """One table entry (:class:`adapters.wire.table.CommandSpec`) in this table's terms.

    ``request`` layouts: the first is what we encode, any decodes (chosen by size). ``ack`` layouts
    likewise; empty means the command takes no ACK. ``session`` is what a sender uses (0 none, 1
    tolerant, 2 = a free session 2..31, resent ``retries`` times ``timeout`` seconds apart).
    ``defaults`` fill missing request fields; ``fixed`` values are forced on encode and must match on
    decode (a preset of a shared id). ``firmware`` (the table's variant) None means both generations;
    ``handler`` the adapter method that takes the push."""
    return CommandSpec(
        name, cmd_set, cmd_id, request, ack, ack_codes, direction, firmware, defaults, fixed, section, doc,
        Delivery(int(session), timeout, retries), handler=handler,
    )  # fmt: skip


def _gs(
    cmd_id: int,
    name: str,
    request: PayloadCodec | tuple[PayloadCodec, ...],
    ack: tuple[PayloadCodec, ...],
    doc: str,
) -> CommandSpec:
    """A seed 004 ground-station command: session 2, 500 ms x 2 retries (OSDK mission timing)."""
    requests = request if isinstance(request, tuple) else (request,)
    section = f"seed 004 0x03,0x{cmd_id:02X}"
    return _spec(name, 0x03, cmd_id, requests, ack, GS_ACK_TEXT, section=section, doc=doc)


_NOTES_ACT = "PROTOCOL-NOTES Activation and version"
_NOTES_CTL = "PROTOCOL-NOTES control (0x01) and telemetry"
_OSDK_SUB = "OSDK 3.9.0 dji_subscription.cpp"

# fmt: off
_SPECS: tuple[CommandSpec, ...] = (
    # ---- activation set 0x00
    _spec(
        "get_version", 0x00, 0x00, (ARBITRARY,), (VERSION_REPLY,), VERSION_ACK,
        timeout=1.0, retries=3, section=_NOTES_ACT, doc="protocol version and activation state",
    ),
    _spec(
        "activate", 0x00, 0x01, (ACTIVATE,), (U16_ACK,), ACTIVATION_ACK, timeout=1.0, retries=3,
        defaults=types.MappingProxyType({"api_level": 2, "bundle_id": b"0" * 32}),
        section=_NOTES_ACT, doc="44 bytes; other command sets work only after activation",
    ),
    _spec(
        "set_broadcast_frequency", 0x00, 0x10, (BROADCAST_FREQUENCY,), (U16_ACK,), FREQUENCY_ACK,
        timeout=0.1, retries=1, section=_NOTES_CTL, doc="byte i = rate code of flight-data item i",
    ),
    # ---- control set 0x01
    _spec(
        "obtain_control", 0x01, 0x00, (OBTAIN_CONTROL,), (U16_ACK,), CONTROL_ACK,
        section=_NOTES_CTL, doc="priority RC > mobile > onboard",
    ),
    _spec(
        "flight_task", 0x01, 0x01, (FLIGHT_TASK,), (U16_ACK,), FLIGHT_TASK_ACK, firmware="new",
        section=_NOTES_CTL, doc="takeoff, landing, go home, motors",
    ),
    _spec(
        "flight_task", 0x01, 0x01, (FLIGHT_TASK_M100,), (U16_ACK,), FLIGHT_TASK_M100_ACK, firmware="m100",
        section=_NOTES_CTL, doc="legacy M100 form: {cmd sequence, code}",
    ),
    _spec(
        "movement_control", 0x01, 0x03, (MOVEMENT,), session=SessionMode.NO_ACK, retries=0,
        section=_NOTES_CTL, doc="virtual stick; stream at up to 50 Hz, no ACK, no hold time",
    ),
    _spec(
        "emergency_brake", 0x01, 0x03, (ADVANCED_MOVEMENT,), session=SessionMode.NO_ACK, retries=0,
        firmware="new", fixed=EMERGENCY_BRAKE_VALUES, section=_NOTES_CTL,
        doc="advanced movement preset 48 01 + six f32 zeros (new FW >= 3.2.36.6)",
    ),
    _spec(
        "advanced_movement_control", 0x01, 0x03, (ADVANCED_MOVEMENT,), session=SessionMode.NO_ACK,
        retries=0, firmware="new", section="OSDK Control::AdvancedCtrlData",
        doc="26-byte movement control with feed-forward (any flag other than the brake preset)",
    ),
    # ACK width not confirmed: the notes give the codes only; u16 like the rest of the control set.
    _spec("arm", 0x01, 0x05, (ARM,), (U16_ACK,), ARM_ACK, section=_NOTES_CTL, doc="arm/disarm motors"),
    _spec(
        "kill_switch", 0x01, 0x06, (KILL_SWITCH,), (U16_ACK,), firmware="new", section=_NOTES_CTL,
        doc="FW >= 3.3; stops motors: a last resort, never on a mere link loss",
    ),
    _spec(
        "go_home_altitude_read", 0x01, 0x41, (GO_HOME_ALTITUDE_READ,), GO_HOME_ALTITUDE_ACKS, PARAM_ACK,
        firmware="new", fixed=types.MappingProxyType({"hash": GO_HOME_ALTITUDE_HASH}),
        section="OSDK 3.9 dji_flight_assistant_module (parameterRead 0x01 0x41)",
        doc="read the go-home altitude (m above take-off); ACK {ret, hash, value held}",
    ),
    _spec(
        "go_home_altitude_write", 0x01, 0x42, (GO_HOME_ALTITUDE_WRITE,), GO_HOME_ALTITUDE_ACKS, PARAM_ACK,
        firmware="new", fixed=types.MappingProxyType({"hash": GO_HOME_ALTITUDE_HASH}),
        section="OSDK 3.9 dji_flight_assistant_module (parameterWrite 0x01 0x42)",
        doc="go-home altitude (m above take-off), 20..500; ACK {ret, hash, value now held}",
    ),
    # ---- push set 0x02 (from the flight controller)
    _spec(
        "flight_data_push", 0x02, 0x00, (FlightDataCodec("new"),), direction=FROM_FC,
        session=SessionMode.NO_ACK, retries=0, firmware="new", section=_NOTES_CTL,
        doc="u16 bitmap + present items (telemetry.py)", handler="_on_flight_data",
    ),
    _spec(
        "flight_data_push", 0x02, 0x00, (FlightDataCodec("m100"),), direction=FROM_FC,
        session=SessionMode.NO_ACK, retries=0, firmware="m100", section=_NOTES_CTL,
        doc="u16 bitmap + present items, M100 layout (telemetry.py)", handler="_on_flight_data",
    ),
    # The FC picks the session; when it is > 0 the onboard side ACKs with 00 00 (same session and seq).
    _spec(
        "lost_authority_push", 0x02, 0x01, (LOST_AUTHORITY,), (U16_ACK,), LOST_AUTHORITY_ACK,
        direction=FROM_FC, defaults=types.MappingProxyType({"reason": 4}), section=_NOTES_CTL,
        doc="RC or mobile app took over: end DRC motion (joystick_invalid_notify reason 4)",
        handler="_on_lost_authority",
    ),
    _spec(
        "subscription_data_push", 0x02, 0x05, (PACKAGE_DATA,), direction=FROM_FC,
        session=SessionMode.NO_ACK, retries=0, firmware="new", section=_OSDK_SUB,
        doc="one subscribed package: u8 id + its topics' structs (subscription.decode_package)",
    ),
    _spec(
        "status_push", 0x02, 0x03, (STATUS_PUSH,), direction=FROM_FC, session=SessionMode.NO_ACK,
        retries=0, section="seed 004 0x02,0x03", doc="current mission status, shape by mission_type",
        handler="_on_status",
    ),
    _spec(
        "event_push", 0x02, 0x04, (EVENT_PUSH,), direction=FROM_FC, session=SessionMode.NO_ACK,
        retries=0, section="seed 004 0x02,0x04", doc="waypoint mission event, shape by incident_type",
        handler="_on_event",
    ),
    # ---- data subscription set 0x0B (firmware 3.3+; subscription.py), OSDK's timing: 500 ms x 2 / x 1
    _spec(
        "subscribe_verify", 0x0B, 0x00, (VERIFY,), (U8_ACK,), SUBSCRIBE_ACK, firmware="new",
        section=_OSDK_SUB, doc="match the topic database version (0x00000100)",
    ),
    _spec(
        "subscribe_add_package", 0x0B, 0x01, (ADD_PACKAGE,), (U8_ACK,), SUBSCRIBE_ACK, retries=1,
        firmware="new", section=_OSDK_SUB, doc="start pushing package 0..4: its rate and topic UIDs",
    ),
    _spec(
        "subscribe_reset", 0x0B, 0x02, (RESET,), (U8_ACK,), SUBSCRIBE_ACK, retries=1,
        firmware="new", section=_OSDK_SUB, doc="remove every package",
    ),
    _spec(
        "subscribe_remove_package", 0x0B, 0x03, (PACKAGE_ID,), (U8_ACK,), SUBSCRIBE_ACK, retries=1,
        firmware="new", section=_OSDK_SUB, doc="stop one package",
    ),
    # ---- ground station set 0x03 (seed 004)
    _gs(0x10, "wp_init", WP_INIT, (U8_ACK,), "upload waypoint task; ACK always 0: validate yourself"),
    _gs(
        0x11, "wp_upload", (WAYPOINT, WAYPOINT_SEED), (Layout((_ACK, _f("index", "B"))),),
        "upload waypoint with index: 90 bytes (OSDK), 87 accepted (seed struct + index)",
    ),
    _gs(0x12, "wp_start_stop", Layout((_f("start", "B", "", "0 start, 1 cancel"),)), (U8_ACK,), "start/stop"),
    _gs(0x13, "wp_pause_resume", Layout((_f("pause", "B", "", "0 pause, 1 resume"),)), (U8_ACK,), "pause"),
    _gs(0x14, "wp_download_init", ARBITRARY, (Layout((_ACK, *WP_INIT_FIELDS)),), "download the task (1+51)"),
    _gs(
        0x15, "wp_download_point", Layout((_f("index", "B"),)),
        # {u8 ack, 90-byte waypoint} = 91 (notes), or the seed's {ack, index, 86-byte struct} = 88.
        (
            BitLayout((_ACK, *_waypoint_fields(16)), _WP_ACTION_BITS),
            BitLayout((_ACK, *_waypoint_fields(15)), _WP_ACTION_BITS),
        ),
        "download one waypoint",
    ),
    _gs(
        0x16, "wp_set_idle_velocity", Layout((_f("idle_velocity", "f", "m/s"),)),  # seed: "idle_veloctity"
        (Layout((_ACK, _f("idle_velocity", "f", "m/s"))),), "set idle velocity",  # seed: "idle_velcity"
    ),
    _gs(
        0x17, "wp_get_idle_velocity", ARBITRARY, (Layout((_ACK, _f("idle_velocity", "f", "m/s"))),),
        "read idle velocity",
    ),
    _gs(
        0x20, "hp_upload_start", HP_SETTING, (Layout((_ACK, _f("max_radius", "f", "m"))),),
        "upload and start",
    ),
    _gs(0x21, "hp_stop", ARBITRARY, (U8_ACK,), "stop hotpoint mission"),
    _gs(0x22, "hp_pause_resume", Layout((_f("pause", "B", "", "0 pause, 1 resume"),)), (U8_ACK,), "pause"),
    _gs(
        0x23, "hp_set_idle_velocity",
        Layout((_f("is_clockwise", "B"), _f("idle_velocity", "f", "m/s"))), (U8_ACK,), "set velocity",
    ),
    _gs(0x24, "hp_set_radius", Layout((_f("radius", "f", "m"),)), (U8_ACK,), "set radius"),
    _gs(0x25, "hp_reset_yaw", ARBITRARY, (U8_ACK,), "reset yaw"),
    _gs(
        0x26, "hp_download", ARBITRARY,
        # {ack, 51-byte setting} = 52; OSDK's HotPointReadInternal also allows a trailing extraByte
        # ("TODO fix/remove once verified with FC team"), so 53 decodes too.
        (
            Layout((_ACK, *HP_SETTING_FIELDS)),
            Layout((_ACK, *HP_SETTING_FIELDS, _f("extra_byte", "B", "", "seen by OSDK, meaning unknown"))),
        ),
        "download hotpoint task",
    ),
    # seed: "enable auto-radiu mode", struct hotpoint_auto_radiu
    _gs(
        0x27, "hp_auto_radius",
        Layout((_f("on_off", "B", "", "1 enable, 0 disable"), _f("rate", "b", "", "radius change rate"))),
        (U8_ACK,), "auto radius mode",
    ),
    _gs(0x30, "fm_upload_start", FM_SETTING, (U8_ACK,), "upload and start follow me"),
    _gs(0x31, "fm_stop", ARBITRARY, (U8_ACK,), "stop follow me"),
    _gs(0x32, "fm_pause_resume", Layout((_f("pause", "B", "", "0 pause, 1 resume"),)), (U8_ACK,), "pause"),
    _spec(
        "fm_update_target", 0x03, 0x33, (FM_TARGET,), session=SessionMode.NO_ACK, retries=0,
        section="seed 004 0x03,0x33", doc="target position; NO ACK",
    ),
)
# fmt: on


# THE table: (cmd_set, cmd_id) -> the specs sharing that id, in decode-preference order.
COMMAND_TABLE = Table(_SPECS, variants=FIRMWARES, variant_noun="firmware")
TABLE = COMMAND_TABLE.by_key
BY_NAME = COMMAND_TABLE.by_name
COMMAND_NAMES: tuple[str, ...] = COMMAND_TABLE.names


# --------------------------------------------------------------------------------------------------
# Lookup, encode, decode


def spec_for(name: str, firmware: str = "new") -> CommandSpec:
    """The spec of a command name for this firmware, or :class:`UnknownCommandError` listing the names."""
    return COMMAND_TABLE.named(name, check_firmware(firmware))


def specs_at(cmd_set: int, cmd_id: int, firmware: str = "new") -> tuple[CommandSpec, ...]:
    return COMMAND_TABLE.at((cmd_set, cmd_id), check_firmware(firmware))


def encode_request(name: str, fields: Mapping[str, Any] | None = None, firmware: str = "new") -> bytes:
    """The payload (after CmdSet/CmdID) of command ``name``: missing fields take the spec's defaults,
    then zero. Raises :class:`UnknownCommandError` or :class:`LayoutError` (unknown field, out of range)."""
    spec = spec_for(name, firmware)
    return spec.request[0].encode(spec.values(fields))


def encode_ack_payload(name: str, fields: Mapping[str, Any] | None = None, firmware: str = "new") -> bytes:
    """The raw ACK value answering command ``name`` (what an ACK frame's data holds)."""
    spec = spec_for(name, firmware)
    if not spec.reply:
        raise LayoutError(f"{name} takes no ACK")
    return spec.reply[0].encode(dict(fields or {}))


def _decode_with(
    codecs: tuple[PayloadCodec, ...], data: bytes, fixed: Mapping[str, Any] = EMPTY
) -> dict[str, Any] | None:
    """The first layout that has the payload's size, decodes it and matches the fixed values."""
    for codec in codecs:
        if codec.size is not None and codec.size != len(data):
            continue
        try:
            fields = codec.decode(data)
        except LayoutError:
            continue
        if all(fields.get(k) == v for k, v in fixed.items()):
            return fields
    return None


def decode_request(cmd_set: int, cmd_id: int, payload: bytes, firmware: str = "new") -> Message:
    """Decode a command or push payload. :class:`UnknownCommandError` if the id is not in the table,
    :class:`LayoutError` if the payload fits none of its layouts."""
    specs = specs_at(cmd_set, cmd_id, firmware)
    if not specs:
        raise UnknownCommandError(f"no command 0x{cmd_set:02X} 0x{cmd_id:02X} on firmware {firmware!r}")
    for spec in specs:
        fields = _decode_with(spec.request, bytes(payload), spec.fixed)
        if fields is not None:
            return Message(spec.name, cmd_set, cmd_id, fields)
    wants = "; ".join(f"{s.name}: {sizes_text(s.request)}" for s in specs)
    detail = ""
    for spec in specs:  # say why a size match still failed (bad selector, bitmap/length mismatch)
        for codec in spec.request:
            if codec.size is None or codec.size == len(payload):
                try:
                    codec.decode(bytes(payload))
                except LayoutError as exc:
                    detail = f" ({exc})"
    raise LayoutError(
        f"0x{cmd_set:02X} 0x{cmd_id:02X} payload of {len(payload)} bytes fits none of {wants}{detail}"
    )


def decode_ack(name: str, data: bytes, firmware: str = "new") -> Message:
    """Decode the raw ACK value of a frame already matched to command ``name``."""
    spec = spec_for(name, firmware)
    if not spec.reply:
        raise LayoutError(f"{name} takes no ACK")
    fields = _decode_with(spec.reply, bytes(data))
    if fields is None:
        raise LayoutError(f"{name} ACK of {len(data)} bytes, expected {sizes_text(spec.reply)}")
    return Message(spec.name, spec.cmd_set, spec.cmd_id, fields, is_reply=True)


def ack_text(spec: CommandSpec, code: int) -> str | None:
    """The documented meaning of an ACK code for this command, if any."""
    return spec.reply_codes.get(code)
