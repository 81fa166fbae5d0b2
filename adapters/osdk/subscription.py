"""Onboard SDK data subscription (command set ``0x0B``, pushes ``0x02 0x05``): the topic table, the
payload layouts, and the flight controller's side of the protocol, as DJI's Onboard-SDK 3.x library
(``dji_subscription.cpp``, ``dji_telemetry.hpp``; checked against tag 3.9.0) speaks it to an A3/N3
(M600/M210) on firmware 3.3 and later.

The protocol, byte by byte (every multi-byte value little-endian, structs ``#pragma pack(1)``):

=================  ==============================================  ========================================
command            request payload                                 ACK payload
=================  ==============================================  ========================================
0x0B 0x00 verify   u32 database version, ``0x00000100``            u8 :data:`SUBSCRIBE_ACK` code
0x0B 0x01 add      u8 package id (0..4), u16 frequency (Hz),       u8 code
                   u8 config (1: an 8-byte time stamp leads the
                   data), u8 topic count, then one u32 UID each
0x0B 0x02 reset    u8 (OSDK sends 0): remove every package          u8 code
0x0B 0x03 remove   u8 package id                                   u8 code
0x02 0x05 push     u8 package id, [u32 ms, u32 ns when config 1],  (none: session 0)
                   then each topic's struct in request order
=================  ==============================================  ========================================

The library sends all four commands on a free session 2..31 and reads the first byte of the ACK
(``subscribeACK``); 0 is success. ``0x0B 0x04`` (update frequency), ``0x05`` (pause/resume) and
``0x06`` (get config) exist in OSDK's command list without an API or a payload layout, so they are not
modelled here. A push is copied whole (``getBufferSize()`` bytes after the package id) into the
package's buffer, at the offsets of the topics as the add request listed them: the data must be
exactly the concatenation of :attr:`Topic.codec` in that order.

:data:`TOPICS` is the one table: every topic of OSDK 3.9.0's ``TopicDataBase`` with its UID, packed
layout (sizes checked with ``sizeof`` against the 3.9.0 headers), the highest rate the FC offers and
how its value is read from the flight controller's telemetry items (:data:`SOURCE_ITEMS`).

The flight controller's rules (:class:`FcSubscriptions`), where OSDK documents only the ACK codes:

* verify: the version must be ``0x00000100`` (else 0x02 "version does not match");
* add: checked in this order: package id < 5 (0x03), package free (0x04), at least one topic (0x20),
  the count matches the UIDs sent (0x21), every UID known (0x22), config 0 or 1 (0x01: the data length
  would be unknown), 1 <= frequency <= the lowest maximum rate of its topics (0x06; the library's own
  client-side rule), data (with the time stamp) <= 250 bytes (0x07; the library's limit), every topic's
  source present (0x25 "source device offline": RTK topics on an aircraft without RTK, which DJI's
  telemetry sample expects and reports as "RTK Not Available"). A payload that fits no layout: 0x01.
* remove: package id < 5 (0x03) and added (0x05); reset always succeeds.
* pushes: each package at its own frequency from the moment it is added, a few frames per call to
  catch up (so 200 Hz holds on a 100 Hz tick) and never an unbounded burst after a stall.

Owns: the topic table, the subscription layouts and codes, :class:`FcSubscriptions` (sans-I/O: values
and a clock in, payloads out). Must not know frames, sessions, links or the simulator's physics (it
reads values through a :data:`Sources` mapping).

Why this module is longer than 500 lines: it is the declarative table of OSDK 3.9.0's 45 subscription
topics with their layouts, and the sans-I/O package logic both the simulator and the tests share; its
length is the table's.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from adapters.osdk.telemetry import (
    BATTERY_NEW,
    CONTROL_DEVICE,
    GPS_DETAIL,
    MAG,
    NEW_ITEMS,
    POSITION_NEW,
    QUATERNION,
    RC,
    RTK,
    VELOCITY_NEW,
)
from adapters.wire.bits import BitLayout, Bits
from adapters.wire.layout import Field, Layout, LayoutError, Tail

__all__ = [
    "ADD_PACKAGE",
    "BAD_PAYLOAD_ACK",
    "BY_NAME",
    "BY_UID",
    "DB_VERSION",
    "MAX_PACKAGES",
    "MAX_PACKAGE_DATA",
    "PACKAGE_DATA",
    "PACKAGE_ID",
    "RESET",
    "SOURCE_ITEMS",
    "SUBSCRIBE_ACK",
    "TIMESTAMP",
    "TOPICS",
    "VERIFY",
    "FcSubscriptions",
    "Package",
    "Sources",
    "Topic",
    "add_package_fields",
    "decode_package",
    "encode_package",
]

DB_VERSION = 0x00000100  # OSDK DBVersion, sent by verify()
MAX_PACKAGES = 5  # DataSubscription::MAX_NUMBER_OF_PACKAGE
MAX_PACKAGE_DATA = 250  # ADD_PACKAEG_DATA_LENGTH: the library refuses bigger packages itself
MAX_CATCH_UP = 8  # pushes per package per call at most (a 400 Hz package on a 50 Hz caller)

# OSDK ErrorCode::SubscribeACK (dji_error.cpp) with the library's texts (dji_ack.cpp, "SUBSCRIBER_" cut).
SUBSCRIBE_ACK: dict[int, str] = {
    0x00: "success",
    0x01: "illegal data length",
    0x02: "version does not match",
    0x03: "package out of range",
    0x04: "package already exists",
    0x05: "package does not exist",
    0x06: "illegal frequency",
    0x07: "package too large",
    0x08: "pipeline overflow",
    0x09: "internal error 0x09",
    0x20: "package empty",
    0x21: "incorrect number of topics",
    0x22: "illegal UID",
    0x23: "permission deny",
    0x24: "multiple subscribe",
    0x25: "source device offline",
    0x48: "paused",
    0x49: "resumed",
    0x4A: "internal error 0x4A",
    0x50: "failed authentication",
    0x51: "version too far",
    0x59: "version unknown error",
    0xFF: "internal error 0xFF",
}
SUCCESS, ILLEGAL_DATA_LENGTH, VERSION_DOES_NOT_MATCH = 0x00, 0x01, 0x02
PACKAGE_OUT_OF_RANGE, PACKAGE_ALREADY_EXISTS, PACKAGE_DOES_NOT_EXIST = 0x03, 0x04, 0x05
ILLEGAL_FREQUENCY, PACKAGE_TOO_LARGE = 0x06, 0x07
PACKAGE_EMPTY, INCORRECT_NUM_OF_TOPICS, ILLEGAL_UID, SOURCE_DEVICE_OFFLINE = 0x20, 0x21, 0x22, 0x25


def _f(name: str, code: str, unit: str = "", doc: str = "", count: int = 1) -> Field:
    return Field(name, code, count=count, unit=unit, doc=doc)


# --------------------------------------------------------------------------------------------------
# Command payloads


def _uids_decode(raw: bytes) -> list[int]:
    if len(raw) % 4:
        raise LayoutError(f"topic UIDs: {len(raw)} bytes is not a whole number of u32")
    return [int.from_bytes(raw[i : i + 4], "little") for i in range(0, len(raw), 4)]


def _uids_encode(uids: Any) -> bytes:
    if not isinstance(uids, list | tuple) or not all(isinstance(u, int) and 0 <= u < 1 << 32 for u in uids):
        raise LayoutError("uids: expected a list of u32 topic UIDs")
    return b"".join(u.to_bytes(4, "little") for u in uids)


VERIFY = Layout((_f("version", "I", "", "subscription database version, 0x00000100"),))
# SubscriptionPackage::PackageInfo (5 bytes) + uidList[numberOfTopics] (serializePackageInfo).
ADD_PACKAGE = Layout(
    (
        _f("package_id", "B", "", "0..4"),
        _f("frequency", "H", "Hz", "push rate of the whole package"),
        _f("config", "B", "", "1: an 8-byte time stamp leads the data"),
        _f("topic_count", "B", "", "number of UIDs that follow"),
    ),
    tail=Tail("uids", "u32 topic UIDs in the data's order", _uids_decode, _uids_encode, 4 * 64),
)
RESET = Layout((_f("reserved", "B", "", "OSDK sends 0"),))
PACKAGE_ID = Layout((_f("package_id", "B", "", "0..4"),))
PACKAGE_DATA = Layout(
    (_f("package_id", "B"),),
    tail=Tail("data", "[time stamp] + the topics' structs in request order (decode_package)", max_len=255),
)
# The 8 bytes in front of the topics when config is 1 (OSDK TimeStamp; the library skips them).
TIMESTAMP = Layout((_f("time_ms", "I", "ms"), _f("time_ns", "I", "ns")))
# Every subscription command: a u8 code answers a payload that fits no layout.
BAD_PAYLOAD_ACK: dict[str, int] = {
    name: ILLEGAL_DATA_LENGTH
    for name in ("subscribe_verify", "subscribe_add_package", "subscribe_reset", "subscribe_remove_package")
}


# --------------------------------------------------------------------------------------------------
# Topic layouts (dji_telemetry.hpp, packed; the broadcast items' layouts where the struct is the same)


def _vec3(unit: str, doc: str = "", names: tuple[str, str, str] = ("x", "y", "z"), code: str = "f") -> Layout:
    return Layout(tuple(_f(n, code, unit, doc) for n in names))


def _one(name: str, code: str, unit: str = "", doc: str = "") -> Layout:
    return Layout((_f(name, code, unit, doc),))


def _flags(carrier: str, code: str, parts: Sequence[tuple[str, int]], *fields: Field) -> BitLayout:
    return BitLayout((*fields, _f(carrier, code)), (Bits(carrier, tuple(parts)),))


# GPSFused: f64 lon, f64 lat (rad), f32 altitude, u16 visibleSatelliteNumber = 22 bytes (longitude first).
GPS_FUSED = Layout(
    (
        _f("longitude", "d", "rad"),
        _f("latitude", "d", "rad"),
        _f("altitude", "f", "m", "barometric, above sea level"),
        _f("visible_satellites", "H"),
    )
)
# Vector3d for TOPIC_GPS_POSITION: x = latitude, y = longitude, z = altitude (dji_telemetry_doc.hpp).
# The doc's units line says rad*1e-7, the struct's comment (uint32)deg*1e7: deg*1e7 like GPSInfo is used.
GPS_POSITION = _vec3("", names=("latitude", "longitude", "altitude"), code="i")
GIMBAL_STATUS = _flags(
    "status",
    "I",
    (
        ("mounted", 1),
        ("busy", 1),
        ("pitch_limited", 1),
        ("roll_limited", 1),
        ("yaw_limited", 1),
        ("calibrating", 1),
        ("previous_calibration_ok", 1),
        ("installed_reversed", 1),
        ("disabled_mvo", 1),
        ("gear_show_unable", 1),
        ("gyro_fault", 1),
        ("esc_pitch_ok", 1),
        ("esc_roll_ok", 1),
        ("esc_yaw_ok", 1),
        ("drone_data_received", 1),
        ("init_complete", 1),  # OSDK names it initUnfinished, documented "1 - init complete"
        ("fw_updating", 1),
        ("reserved", 15),
    ),
)
# HardSyncData: SyncTimestamp {u32 time2p5ms, u32 time1ns, u32 resetTime2p5ms, u16 index, u8 flag} (15)
# + Quaternion (16) + accelerometer Vector3f in g (12) + gyro Vector3f rad/s (12) = 55 bytes.
HARD_SYNC = Layout(
    (
        _f("time_2p5ms", "I", "2.5 ms"),
        _f("time_ns", "I", "ns"),
        _f("reset_time_2p5ms", "I", "2.5 ms"),
        _f("index", "H"),
        _f("flag", "B", "", "1: this packet carries a hardware pulse"),
        *(_f(f"q_{n}", "f") for n in "wxyz"),
        *(_f(f"accel_{n}", "f", "g", "body FRD") for n in "xyz"),
        *(_f(f"gyro_{n}", "f", "rad/s", "body FRD") for n in "xyz"),
    )
)
_LB2_CHANNELS = (
    "roll", "pitch", "yaw", "throttle", "mode", "gear", "camera", "video", "video_pause", "go_home",
    "left_wheel", "right_wheel_button", "rc_c1", "rc_c2", *(f"rc_d{i}" for i in range(1, 9)),
)  # fmt: skip
# RCFullRawData as LB2RcFullRawData: 22 x i16 = 44 bytes (the SBUS view shares the bytes).
RC_FULL_RAW = Layout(tuple(_f(n, "h", "raw", "364..1684, 1024 centre") for n in _LB2_CHANNELS))
# RCWithFlagData: 4 x f32 (pitch, roll, yaw, throttle: -0.999..0.999) + flag bits = 17 bytes.
RC_WITH_FLAG = _flags(
    "flag",
    "B",
    (
        *((n, 1) for n in ("logic_connected", "sky_connected", "ground_connected", "app_connected")),
        ("reserved", 4),
    ),
    *(_f(n, "f") for n in ("pitch", "roll", "yaw", "throttle")),
)
# EscData: 8 x ESCStatusIndividual {i16 current mA, i16 speed rpm, u16 voltage mV, i16 temperature C,
# u16 {stall, empty, unbalanced, escDisconnected, temperatureHigh : 1, reserved : 11}} = 80 bytes.
ESC_COUNT = 8
_ESC_FLAGS = ("stall", "empty", "unbalanced", "disconnected", "temperature_high")
ESC_DATA = BitLayout(
    tuple(
        fld
        for i in range(ESC_COUNT)
        for fld in (
            _f(f"esc{i}_current", "h", "mA"),
            _f(f"esc{i}_speed", "h", "rpm"),
            _f(f"esc{i}_voltage", "H", "mV"),
            _f(f"esc{i}_temperature", "h", "degC"),
            _f(f"esc{i}_status", "H"),
        )
    ),
    tuple(
        Bits(
            f"esc{i}_status",
            (*((f"esc{i}_{p}", 1) for p in _ESC_FLAGS), (f"esc{i}_reserved", 11)),
        )
        for i in range(ESC_COUNT)
    ),
)
RTK_CONNECT_STATUS = _flags("status", "H", (("rtk_connected", 1), ("reserved", 15)))
FLIGHT_ANOMALY = _flags(
    "flags",
    "I",
    (
        *(
            (n, 1)
            for n in (
                "impact_in_air",
                "random_fly",
                "height_ctrl_fail",
                "roll_pitch_ctrl_fail",
                "yaw_ctrl_fail",
                "aircraft_is_falling",
                "strong_wind_level1",
                "strong_wind_level2",
                "compass_installation_error",
                "imu_installation_error",
                "esc_temperature_high",
                "at_least_one_esc_disconnected",
                "gps_yaw_error",
            )
        ),
        ("reserved", 19),
    ),
)
# LocalPositionVO: f32 x (north), y (east), z (down), health bits = 13 bytes.
POSITION_VO = _flags(
    "health",
    "B",
    (("x_health", 1), ("y_health", 1), ("z_health", 1), ("reserved", 5)),
    _f("x", "f", "m", "north (best effort)"),
    _f("y", "f", "m", "east (best effort)"),
    _f("z", "f", "m", "down"),
)
# RelativePosition: the obstacle half of the broadcast position item (6 x f32 m + health bits) = 25.
AVOID_DATA = BitLayout(POSITION_NEW.layout.fields[5:], POSITION_NEW.bits)
HOME_POINT_INFO = Layout((_f("latitude", "d", "rad"), _f("longitude", "d", "rad")))


# --------------------------------------------------------------------------------------------------
# The topic table

#: Values come from a mapping of item name -> fields: the flight-data items of ``telemetry.NEW_ITEMS``
#: (wire units, as the 0x02 0x00 push carries them) plus these two, which that push has no room for.
SOURCE_ITEMS: dict[str, str] = {
    "home": "latitude, longitude (rad) and altitude (m above sea level) of the take-off point; set (0/1)",
    "aircraft": (
        "motors_on, gimbal_mounted, rtk_connected (0/1); north, east, up (m from the take-off point); "
        "accel_x/y/z (m/s^2, body FRD, gravity included, what an IMU reads)"
    ),
}
Sources = Mapping[str, Mapping[str, Any]]


@dataclass(frozen=True, slots=True)
class Topic:
    """One subscribable topic: OSDK ``TopicName`` (lower case, ``TOPIC_`` cut), the UID the FC knows it
    by, its packed struct, the highest rate the FC offers (Hz), the source device it needs (None: the FC
    itself) and how its value is read from the telemetry items."""

    name: str
    uid: int
    codec: Layout | BitLayout
    max_freq: int
    value: Callable[[Sources], Mapping[str, Any]]
    doc: str = ""
    device: str | None = None

    @property
    def size(self) -> int:
        size = self.codec.size
        assert size is not None  # every topic is fixed-size
        return size


def _pick(item: str, *names: str, **renamed: str) -> Callable[[Sources], dict[str, Any]]:
    """The value of a topic whose fields are fields of one item: ``names`` as they are, ``renamed``
    as ``topic_field=item_field``."""

    def value(src: Sources) -> dict[str, Any]:
        it = src[item]
        return {**{n: it[n] for n in names}, **{n: it[m] for n, m in renamed.items()}}

    return value


def _whole(item: str) -> Callable[[Sources], Mapping[str, Any]]:
    return lambda src: src[item]


def _body(src: Sources) -> dict[str, Any]:
    """Ground (north, east, up) acceleration turned into the body's forward, right, up (yaw only)."""
    q, a = src["quaternion"], src["acceleration"]
    yaw = math.atan2(2 * (q["w"] * q["z"] + q["x"] * q["y"]), 1 - 2 * (q["y"] ** 2 + q["z"] ** 2))
    c, s = math.cos(yaw), math.sin(yaw)
    return {"x": a["x"] * c + a["y"] * s, "y": -a["x"] * s + a["y"] * c, "z": a["z"]}


def _gps_fused(src: Sources) -> dict[str, Any]:
    pos = src["position"]
    return {
        "longitude": pos["longitude"],
        "latitude": pos["latitude"],
        "altitude": pos["altitude"],
        "visible_satellites": src["gps"]["num_sv"],
    }


def _gimbal_status(src: Sources) -> dict[str, Any]:
    mounted = src["aircraft"]["gimbal_mounted"]
    ok = {"esc_pitch_ok", "esc_roll_ok", "esc_yaw_ok", "drone_data_received", "init_complete"}
    return {"mounted": mounted, **dict.fromkeys(ok, mounted)}


def _hard_sync(src: Sources) -> dict[str, Any]:
    ts, q, rate, craft = src["timestamp"], src["quaternion"], src["angular_rate"], src["aircraft"]
    ticks = int(ts["time_ms"] / 2.5) & 0xFFFFFFFF
    g = 9.80665
    return {
        "time_2p5ms": ticks,
        "time_ns": ts["time_ns"],
        "reset_time_2p5ms": ticks,
        **{f"q_{n}": q[n] for n in "wxyz"},
        **{f"accel_{n}": craft[f"accel_{n}"] / g for n in "xyz"},
        **{f"gyro_{n}": rate[n] for n in "xyz"},
    }


def _lb2(value: int) -> int:
    """A stick of the RC item (-10000..10000) as the Lightbridge 2 raw channel (364..1684)."""
    return round(1024 + value * 660 / 10000)


def _rc_full_raw(src: Sources) -> dict[str, Any]:
    rc = src["rc"]
    out = {n: _lb2(rc[n]) for n in ("roll", "pitch", "yaw", "throttle")}
    out["mode"] = 364 if rc["mode"] < -4000 else 1684 if rc["mode"] > 4000 else 1024  # P right, F left
    out["gear"] = 1684 if rc["gear"] <= -7000 else 1354  # up -10000, down -4545 in the RC item
    return out | {n: 364 for n in _LB2_CHANNELS[6:14]} | {"left_wheel": 1024}


def _rc_with_flag(src: Sources) -> dict[str, Any]:
    rc = src["rc"]
    sticks = {n: max(-0.999, min(0.999, rc[n] / 10000)) for n in ("pitch", "roll", "yaw", "throttle")}
    return sticks | {"logic_connected": 1, "sky_connected": 1, "ground_connected": 1}


def _esc(src: Sources) -> dict[str, Any]:
    """Six ESCs (an M600) turning while the motors run; the last two report "disconnected"."""
    craft, battery, flight = src["aircraft"], src["battery"], src["status"]["flight"]
    rpm = 0 if not craft["motors_on"] else 4200 if flight == 2 else 1500
    out: dict[str, Any] = {}
    for i in range(ESC_COUNT):
        if i >= 6:
            out[f"esc{i}_disconnected"] = 1
            continue
        out |= {
            f"esc{i}_current": max(-0x8000, min(0x7FFF, battery["current"] // 6)),
            f"esc{i}_speed": rpm,
            f"esc{i}_voltage": max(0, min(0xFFFF, battery["voltage"])),
            f"esc{i}_temperature": 45 if rpm else 25,
        }
    return out


def _position_vo(src: Sources) -> dict[str, Any]:
    craft = src["aircraft"]
    healthy = {"x_health": 1, "y_health": 1, "z_health": 1}
    return {"x": craft["north"], "y": craft["east"], "z": -craft["up"], **healthy}


def _gps_control_level(src: Sources) -> dict[str, Any]:
    return {"level": src["position"]["health"] if src["home"]["set"] else 0}


def _const(**values: Any) -> Callable[[Sources], dict[str, Any]]:
    return lambda src: dict(values)


_RTK = "rtk"
# fmt: off
#: Every topic of OSDK 3.9.0's TopicDataBase, in its order: (name, UID, layout, max Hz, value, doc).
TOPICS: tuple[Topic, ...] = (
    Topic("quaternion", 0xA493281F, QUATERNION, 200, _whole("quaternion"), "body FRD -> ground NED, w x y z"),
    Topic("acceleration_ground", 0x8696C85B, _vec3("m/s^2", "north, east, up"), 200, _whole("acceleration")),
    Topic("acceleration_body", 0xBB17D5FE, _vec3("m/s^2", "forward, right, up"), 200, _body),
    Topic("acceleration_raw", 0xC3503A6E, _vec3("m/s^2", "IMU, body FRD"), 400,
          _pick("aircraft", x="accel_x", y="accel_y", z="accel_z")),
    Topic("velocity", 0x18FB271D, VELOCITY_NEW, 200, _whole("velocity"), "north, east, up m/s + health"),
    Topic("angular_rate_fusioned", 0x3599C4BE, _vec3("rad/s", "ground NED"), 200, _whole("angular_rate")),
    Topic("angular_rate_raw", 0x700389EE, _vec3("rad/s", "IMU, body FRD"), 400, _whole("angular_rate")),
    Topic("altitude_fusioned", 0x11E9C81A, _one("altitude", "f", "m"), 200, _pick("position", "altitude")),
    Topic("altitude_barometer", 0x27396A39, _one("altitude", "f", "m"), 200, _pick("position", "altitude")),
    Topic("height_homepoint", 0x252C164B, _one("altitude", "f", "m", "sea level, at the last take-off"), 1,
          _pick("home", "altitude")),
    Topic("height_fusion", 0x87CF419D, _one("height", "f", "m", "above ground"), 100,
          _pick("position", "height")),
    Topic("gps_fused", 0x4B19A8C7, GPS_FUSED, 50, _gps_fused),
    Topic("gps_date", 0x598F79BC, _one("date", "I", "yyyymmdd"), 5, _pick("gps", "date")),
    Topic("gps_time", 0xD48912C9, _one("time", "I", "hhmmss"), 5, _pick("gps", "time")),
    Topic("gps_position", 0x0C949E94, GPS_POSITION, 5,
          _pick("gps", "latitude", "longitude", altitude="hfsl"), "1e-7 deg, 1e-7 deg, mm"),
    Topic("gps_velocity", 0x7AC7EB80, Layout(GPS_DETAIL.fields[5:8]), 5,
          _pick("gps", "velocity_n", "velocity_e", "velocity_d"), "cm/s NED"),
    Topic("gps_details", 0x81FED54E, Layout(GPS_DETAIL.fields[8:]), 5,
          _pick("gps", *(f.name for f in GPS_DETAIL.fields[8:]))),
    Topic("rtk_position", 0x1DF9A6B6, Layout(RTK.fields[2:5]), 5,
          _pick("rtk", "longitude", "latitude", "hfsl"), "deg, deg, m", device=_RTK),
    Topic("rtk_velocity", 0x763D13C3, Layout(RTK.fields[5:8]), 5,
          _pick("rtk", "velocity_n", "velocity_e", "velocity_d"), device=_RTK),
    Topic("rtk_yaw", 0xF45D73FD, Layout(RTK.fields[8:9]), 5, _pick("rtk", "yaw"), device=_RTK),
    Topic("rtk_position_info", 0xDA4A57B5, Layout(RTK.fields[9:10]), 5, _pick("rtk", "pos_health_flag"),
          device=_RTK),
    Topic("rtk_yaw_info", 0xCB72B9E3, Layout(RTK.fields[10:11]), 5, _pick("rtk", "yaw_health_flag"),
          device=_RTK),
    Topic("compass", 0xDF3D72B7, MAG, 100, _whole("mag")),
    Topic("rc", 0x739F7FE4, RC, 50, _whole("rc"), "sticks -10000..10000, mode P -8000 A 0 F 8000"),
    Topic("gimbal_angles", 0x01F71678, _vec3("deg", names=("pitch", "roll", "yaw")), 50,
          _pick("gimbal", "pitch", "roll", "yaw")),
    Topic("gimbal_status", 0x8B6CD45C, GIMBAL_STATUS, 50, _gimbal_status),
    Topic("status_flight", 0x20CFB02A, _one("flight", "B", "", "0 stopped, 1 on ground, 2 in air"), 50,
          _pick("status", "flight")),
    Topic("status_displaymode", 0x1A67D6A1, _one("display_mode", "B"), 50, _pick("status", "display_mode")),
    Topic("status_landinggear", 0x772D6E22, _one("gear", "B"), 50, _pick("status", "gear")),
    Topic("status_motor_start_error", 0x3A41E909, _one("error", "H"), 50, _pick("status", "error")),
    Topic("battery_info", 0x69779DD9, BATTERY_NEW, 50, _whole("battery")),
    Topic("control_device", 0x667BA86A, CONTROL_DEVICE, 50, _whole("control_device")),
    Topic("hard_sync", 0xECBEF06D, HARD_SYNC, 400, _hard_sync),
    Topic("gps_signal_level", 0xA6A0395F, _one("level", "B", "", "0..5"), 50,
          _pick("position", level="health")),
    Topic("gps_control_level", 0xE30B17B0, _one("level", "B", "", "0 until home is set"), 50,
          _gps_control_level),
    Topic("rc_full_raw_data", 0x16EC4D0E, RC_FULL_RAW, 50, _rc_full_raw),
    Topic("rc_with_flag_data", 0xFE04CFCD, RC_WITH_FLAG, 50, _rc_with_flag),
    Topic("esc_data", 0xAAA0F589, ESC_DATA, 50, _esc),
    Topic("rtk_connect_status", 0x6F349326, RTK_CONNECT_STATUS, 50, _pick("aircraft", "rtk_connected")),
    Topic("gimbal_control_mode", 0x326A446D, _one("mode", "B"), 50, _const(mode=0)),
    Topic("flight_anomaly", 0x0A624B4B, FLIGHT_ANOMALY, 50, _const()),
    Topic("position_vo", 0xD3462697, POSITION_VO, 200, _position_vo),
    Topic("avoid_data", 0xF6405DAA, AVOID_DATA, 100,
          _pick("position", *(n for n in AVOID_DATA.field_names))),
    Topic("home_point_set_status", 0xB5C2211F, _one("status", "B", "", "0 fail, 1 success"), 50,
          _pick("home", status="set")),
    Topic("home_point_info", 0xBFE4B520, HOME_POINT_INFO, 50, _pick("home", "latitude", "longitude")),
)
# fmt: on
BY_UID: dict[int, Topic] = {t.uid: t for t in TOPICS}
BY_NAME: dict[str, Topic] = {t.name: t for t in TOPICS}
assert len(BY_UID) == len(BY_NAME) == len(TOPICS)


def _topic(ref: str | int | Topic) -> Topic:
    if isinstance(ref, Topic):
        return ref
    found = BY_UID.get(ref) if isinstance(ref, int) else BY_NAME.get(ref)
    if found is None:
        what = f"UID 0x{ref:08X}" if isinstance(ref, int) else repr(ref)
        raise LayoutError(f"unknown topic {what}")
    return found


# --------------------------------------------------------------------------------------------------
# Host side: what the library encodes and decodes


def add_package_fields(
    package_id: int, topics: Iterable[str | int | Topic], frequency: int, *, timestamp: bool = False
) -> dict[str, Any]:
    """The fields of a ``0x0B 0x01`` request (for ``commands.encode_request("subscribe_add_package")``),
    as ``SubscriptionPackage::serializePackageInfo`` lays them out."""
    uids = [_topic(t).uid for t in topics]
    return {
        "package_id": package_id,
        "frequency": frequency,
        "config": int(timestamp),
        "topic_count": len(uids),
        "uids": uids,
    }


def package_size(topics: Iterable[str | int | Topic], *, timestamp: bool = False) -> int:
    """Bytes of data after the package id (``SubscriptionPackage::getBufferSize``)."""
    return (TIMESTAMP.fixed_size if timestamp else 0) + sum(_topic(t).size for t in topics)


def decode_package(
    data: bytes, topics: Sequence[str | int | Topic], *, timestamp: bool = False
) -> dict[str, dict[str, Any]]:
    """The ``data`` of a ``0x02 0x05`` push (after its package id) as ``{topic name: fields}``, plus
    ``"timestamp"`` when the package has one. Raises :class:`LayoutError` when the length is not the
    package's size (the library would copy the wrong bytes)."""
    want = package_size(topics, timestamp=timestamp)
    if len(data) != want:
        raise LayoutError(f"package data is {len(data)} bytes, its topics need {want}")
    out: dict[str, dict[str, Any]] = {}
    pos = 0
    if timestamp:
        out["timestamp"] = TIMESTAMP.decode(data[: TIMESTAMP.fixed_size])
        pos = TIMESTAMP.fixed_size
    for ref in topics:
        t = _topic(ref)
        out[t.name] = t.codec.decode(bytes(data[pos : pos + t.size]))
        pos += t.size
    return out


def encode_package(
    values: Mapping[str, Mapping[str, Any]],
    topics: Sequence[str | int | Topic],
    *,
    timestamp: Mapping[str, Any] | None = None,
) -> bytes:
    """The data of a push: the time stamp (when given) then each topic's struct, in ``topics`` order."""
    head = TIMESTAMP.encode(timestamp) if timestamp is not None else b""
    return head + b"".join(_topic(t).codec.encode(values.get(_topic(t).name, {})) for t in topics)


# --------------------------------------------------------------------------------------------------
# Flight-controller side


@dataclass
class Package:
    """An added package: its topics in request order, rate, time-stamp flag and next push time."""

    package_id: int
    frequency: int
    timestamp: bool
    topics: tuple[Topic, ...]
    next_due: float
    pushed: int = 0


_ITEM_CODECS = {it.name: it.codec for it in NEW_ITEMS}


class _Cache(Mapping[str, Mapping[str, Any]]):
    """Reads each source item at most once per call (one instant, and the getters may count calls).
    Flight-data items go through their own layout once: missing fields become the zeros the 0x02 0x00
    push would carry, and values take the wire's precision (f32), so both feeds report the same."""

    def __init__(self, sources: Sources) -> None:
        self._sources = sources
        self._seen: dict[str, Mapping[str, Any]] = {}

    def __getitem__(self, name: str) -> Mapping[str, Any]:
        if name not in self._seen:
            raw = self._sources[name]
            codec = _ITEM_CODECS.get(name)
            self._seen[name] = raw if codec is None else codec.decode(codec.encode(raw))
        return self._seen[name]

    def __iter__(self) -> Any:
        return iter(self._sources)

    def __len__(self) -> int:
        return len(self._sources)


@dataclass
class FcSubscriptions:
    """The flight controller's subscription state: answers ``0x0B`` commands with a :data:`SUBSCRIBE_ACK`
    code and produces the ``0x02 0x05`` payloads that fall due. Rules: module docstring.

    ``offline``: source devices that are absent (default RTK: an A3 without the RTK module).
    ``refused``: how often each refusal code was answered (tests read it)."""

    offline: frozenset[str] = frozenset({_RTK})
    packages: dict[int, Package] = field(default_factory=dict)
    refused: dict[int, int] = field(default_factory=dict)

    def handle(self, name: str, fields: Mapping[str, Any], now: float) -> dict[str, int]:
        """Act on a decoded subscription command; returns its ACK fields."""
        action = {
            "subscribe_verify": self._verify,
            "subscribe_add_package": self._add,
            "subscribe_reset": self._reset,
            "subscribe_remove_package": self._remove,
        }[name]
        code = action(fields, now)
        if code:
            self.refused[code] = self.refused.get(code, 0) + 1
        return {"ack": code}

    def _verify(self, f: Mapping[str, Any], now: float) -> int:
        return SUCCESS if f["version"] == DB_VERSION else VERSION_DOES_NOT_MATCH

    def _add(self, f: Mapping[str, Any], now: float) -> int:
        pid, uids = f["package_id"], list(f["uids"])
        if pid >= MAX_PACKAGES:
            return PACKAGE_OUT_OF_RANGE
        if pid in self.packages:
            return PACKAGE_ALREADY_EXISTS
        if f["topic_count"] == 0:
            return PACKAGE_EMPTY
        if f["topic_count"] != len(uids):
            return INCORRECT_NUM_OF_TOPICS
        if any(u not in BY_UID for u in uids):
            return ILLEGAL_UID
        if f["config"] not in (0, 1):
            return ILLEGAL_DATA_LENGTH
        topics = tuple(BY_UID[u] for u in uids)
        if not 1 <= f["frequency"] <= min(t.max_freq for t in topics):
            return ILLEGAL_FREQUENCY
        if package_size(topics, timestamp=bool(f["config"])) > MAX_PACKAGE_DATA:
            return PACKAGE_TOO_LARGE
        if any(t.device in self.offline for t in topics):
            return SOURCE_DEVICE_OFFLINE
        self.packages[pid] = Package(pid, f["frequency"], bool(f["config"]), topics, now)
        return SUCCESS

    def _remove(self, f: Mapping[str, Any], now: float) -> int:
        pid = f["package_id"]
        if pid >= MAX_PACKAGES:
            return PACKAGE_OUT_OF_RANGE
        if self.packages.pop(pid, None) is None:
            return PACKAGE_DOES_NOT_EXIST
        return SUCCESS

    def _reset(self, f: Mapping[str, Any], now: float) -> int:
        self.packages.clear()
        return SUCCESS

    def pushes(self, now: float, sources: Sources) -> list[bytes]:
        """The ``0x02 0x05`` payloads due at ``now``, package by package (at most :data:`MAX_CATCH_UP`
        each; a package further behind skips ahead instead of bursting)."""
        if not self.packages:
            return []
        src = _Cache(sources)
        out: list[bytes] = []
        for pid in sorted(self.packages):
            pkg = self.packages[pid]
            period = 1.0 / pkg.frequency
            burst = 0
            while pkg.next_due <= now and burst < MAX_CATCH_UP:
                out.append(bytes([pid]) + self._data(pkg, src))
                pkg.next_due += period
                pkg.pushed += 1
                burst += 1
            if pkg.next_due <= now:
                pkg.next_due = now + period
        return out

    @staticmethod
    def _data(pkg: Package, src: Sources) -> bytes:
        stamp = {k: src["timestamp"][k] for k in ("time_ms", "time_ns")} if pkg.timestamp else None
        return encode_package({t.name: t.value(src) for t in pkg.topics}, pkg.topics, timestamp=stamp)
