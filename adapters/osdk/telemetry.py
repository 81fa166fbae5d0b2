"""Onboard SDK flight-data push (``0x02 0x00``): a u16 bitmap, then only the present items packed in
bit order (PROTOCOL-NOTES "DJI Onboard SDK: control (0x01) and telemetry (0x02 0x00)").

Two firmware generations lay the items out differently: ``"new"`` (OSDK 3.3+: A3/N3/M600/M210,
bits 0..13) and ``"m100"`` (bits 0..11). Every item is a packed little-endian struct described with
:class:`~adapters.wire.layout.Layout`; the struct layouts of the GPS detail (68 bytes) and RTK (44 bytes)
items were confirmed against DJI Onboard-SDK 3.3 ``dji_telemetry.hpp`` (``GPSInfo``, ``RTK``,
``RelativePosition``, ``SDKInfo``), whose packed sizes add up to the notes' item sizes (arithmetic next
to each layout). Values stay in wire units (radians, 1e-7 degrees, mm, cm/s, raw RC ticks).

Bit-field members (``x : 4``) use the shared :class:`adapters.wire.bits.BitLayout`; ``BitLayout`` and
``Bits`` are re-exported here because tests and older callers import them from this module.

Owns: item layouts, bitmap packing, :class:`FlightDataCodec` (the table's payload codec for the push).
Must not know frames, sessions, clocks or what the gateway does with the values. Sans-I/O.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from adapters.wire.bits import BitLayout, Bits
from adapters.wire.layout import Field, Layout, LayoutError, PayloadCodec

__all__ = [
    "FIRMWARES",
    "ITEMS",
    "M100_ITEMS",
    "NEW_ITEMS",
    "BitLayout",
    "Bits",
    "FlightData",
    "FlightDataCodec",
    "Item",
    "check_firmware",
    "decode_flight_data",
    "encode_flight_data",
    "examples_of",
]

FIRMWARES = ("new", "m100")


def check_firmware(firmware: str) -> str:
    """Reject a firmware setting we do not model (the two layouts differ silently otherwise)."""
    if firmware not in FIRMWARES:
        raise ValueError(f"firmware must be one of {list(FIRMWARES)}, got {firmware!r}")
    return firmware


def examples_of(codec: PayloadCodec) -> list[dict[str, Any]]:
    """Every example a codec offers: one per shape for unions, else its single example."""
    many = getattr(codec, "examples", None)
    return list(many()) if callable(many) else [codec.example()]


# --------------------------------------------------------------------------------------------------
# Items


@dataclass(frozen=True, slots=True)
class Item:
    """One flight-data item: the bitmap ``bit`` that announces it and its packed layout."""

    bit: int
    name: str
    codec: Layout | BitLayout
    doc: str = ""

    @property
    def size(self) -> int:
        size = self.codec.size
        assert size is not None  # every item is fixed-size
        return size


def _f(name: str, code: str, unit: str = "", doc: str = "", count: int = 1) -> Field:
    return Field(name, code, count=count, unit=unit, doc=doc)


# bit 0, new FW: OSDK TimeStamp {u32 time_ms, u32 time_ns} (8) + SyncStamp {u32 time_2p5ms,
# u16 tag, u8 flag} (7) = 15 bytes.
TIMESTAMP_NEW = Layout(
    (
        _f("time_ms", "I", "ms"),
        _f("time_ns", "I", "ns"),
        _f("sync_time_2p5ms", "I", "2.5 ms", "software sync stamp"),
        _f("sync_tag", "H"),
        _f("sync_flag", "B"),
    )
)
# bit 0, M100: LegacyTimeStamp {u32 time, u32 nanoTime, u8 syncFlag} = 9 bytes.
TIMESTAMP_M100 = Layout((_f("time", "I", "tick"), _f("nano_time", "I", "ns"), _f("sync_flag", "B")))
# bit 1: quaternion ground->body, 4 x f32 = 16 bytes (OSDK q0..q3 = w, x, y, z).
QUATERNION = Layout((_f("w", "f"), _f("x", "f"), _f("y", "f"), _f("z", "f")))
# bit 2: acceleration, 3 x f32 = 12 bytes (frame per DJI Assistant's SDK page).
ACCELERATION = Layout((_f("x", "f"), _f("y", "f"), _f("z", "f")))
# bit 3, new FW: Velocity {Vector3f (12), VelocityInfo {health : 1, reserve : 7} (1)} = 13 bytes.
VELOCITY_NEW = BitLayout(
    (
        _f("x", "f", "m/s", "North (ground frame by default)"),
        _f("y", "f", "m/s", "East"),
        _f("z", "f", "m/s", "Up"),
        _f("info", "B"),
    ),
    (Bits("info", (("health", 1), ("reserved", 7))),),
)
# bit 3, M100: LegacyVelocity {3 x f32, health : 1, sensorID : 4, reserve : 3} = 13 bytes.
VELOCITY_M100 = BitLayout(
    (
        _f("x", "f", "m/s", "North"),
        _f("y", "f", "m/s", "East"),
        _f("z", "f", "m/s", "Up"),
        _f("info", "B"),
    ),
    (Bits("info", (("health", 1), ("sensor_id", 4), ("reserved", 3))),),
)
# bit 4: angular rate, 3 x f32 rad/s = 12 bytes.
ANGULAR_RATE = Layout((_f("x", "f", "rad/s"), _f("y", "f", "rad/s"), _f("z", "f", "rad/s")))

_GLOBAL_POSITION = (
    _f("latitude", "d", "rad"),
    _f("longitude", "d", "rad"),
    _f("altitude", "f", "m", "WGS 84 ellipsoid (OSDK)"),
    _f("height", "f", "m", "above takeoff"),
    _f("health", "B", "", "GPS health 0..5, >3 strong"),
)
# bit 5, new FW: GlobalPosition (8+8+4+4+1 = 25) + RelativePosition obstacle distances
# (6 x f32 = 24, + 1 health-bit byte) = 25 -> 50 bytes. Unit: metres. DJI's headers disagree (OSDK 3.3
# dji_telemetry.hpp says cm for the broadcast, 3.8+ and PSDK say m for broadcast and subscription); the
# later headers and the gateway's Cloud API conversion (x 1000 -> mm) follow metres.
POSITION_NEW = BitLayout(
    (
        *_GLOBAL_POSITION,
        _f("obstacle_down", "f", "m"),
        _f("obstacle_front", "f", "m"),
        _f("obstacle_right", "f", "m"),
        _f("obstacle_back", "f", "m"),
        _f("obstacle_left", "f", "m"),
        _f("obstacle_up", "f", "m"),
        _f("obstacle_health", "B"),
    ),
    (
        Bits(
            "obstacle_health",
            (
                ("down_health", 1),
                ("front_health", 1),
                ("right_health", 1),
                ("back_health", 1),
                ("left_health", 1),
                ("up_health", 1),
                ("obstacle_reserved", 2),
            ),
        ),
    ),
)
# bit 5, M100: GlobalPosition only = 25 bytes.
POSITION_M100 = Layout(_GLOBAL_POSITION)
# bit 6, new FW: GPSInfo = PositionTimeStamp {u32 date, u32 time} (8) + i32 lon, lat, HFSL (12)
# + velocityNED 3 x f32 (12) + GPSDetail {6 x f32 (24), 2 x u32 (8), 2 x u16 (4)} (36) = 68 bytes.
# Note the OSDK order: longitude before latitude, in 1e-7 degrees (not radians like bit 5).
GPS_DETAIL = Layout(
    (
        _f("date", "I", "yyyymmdd"),
        _f("time", "I", "hhmmss"),
        _f("longitude", "i", "1e-7 deg"),
        _f("latitude", "i", "1e-7 deg"),
        _f("hfsl", "i", "mm", "height above mean sea level"),
        _f("velocity_n", "f", "cm/s"),
        _f("velocity_e", "f", "cm/s"),
        _f("velocity_d", "f", "cm/s"),
        _f("hdop", "f"),
        _f("pdop", "f"),
        _f("fix", "f", "", "GPS fix state"),
        _f("gnss_status", "f"),
        _f("hacc", "f", "mm", "horizontal accuracy"),
        _f("sacc", "f", "cm/s", "speed accuracy"),
        _f("used_gps", "I", "", "GPS satellites used"),
        _f("used_glonass", "I", "", "GLONASS satellites used"),
        _f("num_sv", "H", "", "satellites used in total"),
        _f("gps_counter", "H", "", "GPS packets sent so far"),
    )
)
# bit 7, new FW: RTK = PositionFrame {date, time (8), PositionData {f64 lon, f64 lat, f32 HFSL} (20)}
# (28) + velocityNED 3 x f32 (12) + i16 yaw (2) + u8 posHealthFlag + u8 yawHealthFlag (2) = 44 bytes.
# RTK longitude/latitude are f64 *degrees* (OSDK PositionData), unlike bit 5's radians.
RTK = Layout(
    (
        _f("date", "I", "yyyymmdd"),
        _f("time", "I", "hhmmss"),
        _f("longitude", "d", "deg"),
        _f("latitude", "d", "deg"),
        _f("hfsl", "f", "m", "height above mean sea level"),
        _f("velocity_n", "f"),
        _f("velocity_e", "f"),
        _f("velocity_d", "f"),
        _f("yaw", "h", "", "azimuth measured by RTK"),
        _f("pos_health_flag", "B", "", "solution type: 0 none, 16 single, 50 narrow-lane fixed, ..."),
        _f("yaw_health_flag", "B"),
    )
)
# magnetometer i16 x 3 = 6 bytes (calibrated; 1000 < |mag| < 2000 normally).
MAG = Layout((_f("x", "h"), _f("y", "h"), _f("z", "h")))
# RC i16 x 6 = 12 bytes: sticks -10000..10000, mode P -8000 / A 0 / F 8000, gear up -10000 / down -4545.
RC = Layout(
    (_f("roll", "h"), _f("pitch", "h"), _f("yaw", "h"), _f("throttle", "h"), _f("mode", "h"), _f("gear", "h"))
)
# gimbal: 3 x f32 degrees + {pitchLimit : 1, rollLimit : 1, yawLimit : 1, reserved : 5} = 13 bytes.
GIMBAL = BitLayout(
    (_f("roll", "f", "deg"), _f("pitch", "f", "deg"), _f("yaw", "f", "deg"), _f("limit", "B")),
    (Bits("limit", (("pitch_limit", 1), ("roll_limit", 1), ("yaw_limit", 1), ("reserved", 5))),),
)
# bit 11, new FW: Status {u8 flight, u8 mode, u8 gear, u8 error} = 4 bytes.
STATUS_NEW = Layout(
    (
        _f("flight", "B", "", "0 stopped, 1 on ground, 2 in air"),
        _f("display_mode", "B", "", "0 manual, 1 attitude, 6 P-GPS, 17 SDK control, ..."),
        _f("gear", "B"),
        _f("error", "B"),
    )
)
# bit 9, M100: u8 flight status = 1 byte.
STATUS_M100 = Layout((_f("flight", "B", "", "1 standby, 2 takeoff, 3 in air, 4 landing, 5 landed"),))
# bit 12, new FW: Battery {u32 capacity, i32 voltage, i32 current, u8 percentage} = 13 bytes.
BATTERY_NEW = Layout(
    (
        _f("capacity", "I", "mAh"),
        _f("voltage", "i", "mV"),
        _f("current", "i", "mA"),
        _f("percentage", "B", "%"),
    )
)
# bit 10, M100: u8 percentage = 1 byte.
BATTERY_M100 = Layout((_f("percentage", "B", "%"),))
# control device: SDKInfo {u8 controlMode, deviceStatus : 3, flightStatus : 1, vrcStatus : 1,
# reserved : 3} = 2 bytes.
CONTROL_DEVICE = BitLayout(
    (_f("control_mode", "B"), _f("status", "B")),
    (
        Bits(
            "status",
            (("device_status", 3), ("flight_status", 1), ("vrc_status", 1), ("reserved", 3)),
        ),
    ),
)

NEW_ITEMS: tuple[Item, ...] = (
    Item(0, "timestamp", TIMESTAMP_NEW),
    Item(1, "quaternion", QUATERNION),
    Item(2, "acceleration", ACCELERATION),
    Item(3, "velocity", VELOCITY_NEW),
    Item(4, "angular_rate", ANGULAR_RATE),
    Item(5, "position", POSITION_NEW),
    Item(6, "gps", GPS_DETAIL),
    Item(7, "rtk", RTK),
    Item(8, "mag", MAG),
    Item(9, "rc", RC),
    Item(10, "gimbal", GIMBAL),
    Item(11, "status", STATUS_NEW),
    Item(12, "battery", BATTERY_NEW),
    Item(13, "control_device", CONTROL_DEVICE),
)
M100_ITEMS: tuple[Item, ...] = (
    Item(0, "timestamp", TIMESTAMP_M100),
    Item(1, "quaternion", QUATERNION),
    Item(2, "acceleration", ACCELERATION),
    Item(3, "velocity", VELOCITY_M100),
    Item(4, "angular_rate", ANGULAR_RATE),
    Item(5, "position", POSITION_M100),
    Item(6, "mag", MAG),
    Item(7, "rc", RC),
    Item(8, "gimbal", GIMBAL),
    Item(9, "status", STATUS_M100),
    Item(10, "battery", BATTERY_M100),
    Item(11, "control_device", CONTROL_DEVICE),
)
ITEMS: dict[str, tuple[Item, ...]] = {"new": NEW_ITEMS, "m100": M100_ITEMS}


# --------------------------------------------------------------------------------------------------
# Push codec


@dataclass(frozen=True, slots=True)
class FlightData:
    """One decoded push. ``unknown`` holds the bytes behind bitmap bits this firmware layout does not
    define (they always come after the known items, so those still decode)."""

    firmware: str
    bitmap: int
    items: dict[str, dict[str, Any]] = field(default_factory=dict)
    unknown: bytes = b""


def _known_mask(items: tuple[Item, ...]) -> int:
    mask = 0
    for it in items:
        mask |= 1 << it.bit
    return mask


def decode_flight_data(payload: bytes, firmware: str = "new") -> FlightData:
    """Decode a ``0x02 0x00`` payload (without CmdSet/CmdID). Raises :class:`LayoutError` when the
    payload is shorter than its bitmap announces, or longer without an unknown bit to explain it."""
    items = ITEMS[check_firmware(firmware)]
    if len(payload) < 2:
        raise LayoutError(f"flight data needs a 2-byte bitmap, got {len(payload)} bytes")
    bitmap = int.from_bytes(payload[:2], "little")
    pos = 2
    out: dict[str, dict[str, Any]] = {}
    for it in items:
        if not bitmap >> it.bit & 1:
            continue
        end = pos + it.size
        if end > len(payload):
            raise LayoutError(
                f"flight data bitmap 0x{bitmap:04X} announces {it.name} (bit {it.bit}, {it.size} bytes) "
                f"at offset {pos}, but the payload is {len(payload)} bytes"
            )
        out[it.name] = it.codec.decode(bytes(payload[pos:end]))
        pos = end
    rest = bytes(payload[pos:])
    if rest and not bitmap & ~_known_mask(items):
        raise LayoutError(f"flight data has {len(rest)} bytes after the items of bitmap 0x{bitmap:04X}")
    return FlightData(firmware, bitmap, out, rest)


def encode_flight_data(
    items: Mapping[str, Mapping[str, Any]],
    firmware: str = "new",
    *,
    unknown_bits: int = 0,
    unknown: bytes = b"",
) -> bytes:
    """Pack the named items (missing fields are zero) behind their bitmap. ``unknown_bits`` and
    ``unknown`` reproduce a push carrying items this layout does not define (simulator, round trips)."""
    table = ITEMS[check_firmware(firmware)]
    names = {it.name for it in table}
    extra = set(items) - names
    if extra:
        raise LayoutError(f"unknown flight data item(s) {sorted(extra)}; known: {[it.name for it in table]}")
    if unknown_bits & _known_mask(table) or not 0 <= unknown_bits <= 0xFFFF:
        raise LayoutError(f"unknown_bits 0x{unknown_bits:X} overlaps the known items or exceeds 16 bits")
    if unknown and not unknown_bits:
        raise LayoutError("unknown bytes need at least one unknown bit")
    bitmap = unknown_bits
    body = bytearray()
    for it in table:
        if it.name in items:
            bitmap |= 1 << it.bit
            body += it.codec.encode(items[it.name])
    return bitmap.to_bytes(2, "little") + bytes(body) + bytes(unknown)


class FlightDataCodec:
    """The command table's payload codec for ``0x02 0x00``: a dict ``{"bitmap": int, <item>: {...},
    "unknown": bytes}`` (``unknown`` only when unknown bits are set)."""

    __slots__ = ("firmware",)

    def __init__(self, firmware: str) -> None:
        self.firmware = check_firmware(firmware)

    @property
    def size(self) -> int | None:
        return None

    @property
    def items(self) -> tuple[Item, ...]:
        return ITEMS[self.firmware]

    def decode(self, data: bytes) -> dict[str, Any]:
        fd = decode_flight_data(data, self.firmware)
        out: dict[str, Any] = {"bitmap": fd.bitmap, **fd.items}
        if fd.bitmap & ~_known_mask(self.items):
            out["unknown"] = fd.unknown
        return out

    def encode(self, values: Mapping[str, Any]) -> bytes:
        values = dict(values)
        bitmap = values.pop("bitmap", None)
        unknown = values.pop("unknown", b"")
        if isinstance(unknown, str):
            unknown = bytes.fromhex(unknown)
        known = _known_mask(self.items)
        unknown_bits = 0 if bitmap is None else int(bitmap) & ~known & 0xFFFF
        payload = encode_flight_data(values, self.firmware, unknown_bits=unknown_bits, unknown=unknown)
        if bitmap is not None and int(bitmap) != int.from_bytes(payload[:2], "little"):
            raise LayoutError(
                f"bitmap 0x{int(bitmap):04X} does not match the items given "
                f"(0x{int.from_bytes(payload[:2], 'little'):04X})"
            )
        return payload

    def example(self) -> dict[str, Any]:
        """Every item present."""
        return self.decode(
            encode_flight_data({it.name: it.codec.example() for it in self.items}, self.firmware)
        )

    def examples(self) -> list[dict[str, Any]]:
        """One push per single item, then all items, then none."""
        out = [
            self.decode(encode_flight_data({it.name: it.codec.example()}, self.firmware)) for it in self.items
        ]
        out.append(self.example())
        out.append(self.decode(encode_flight_data({}, self.firmware)))
        return out
