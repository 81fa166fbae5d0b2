"""OSDK flight-data push (0x02 0x00): item sizes, hand-built vectors, round trips for every bit and
random bitmaps on both firmware layouts."""

from __future__ import annotations

import math
import struct
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from adapters.errors import LayoutError
from adapters.osdk.commands import decode_request
from adapters.osdk.protocol import decode_frame, encode_command
from adapters.osdk.telemetry import (
    ITEMS,
    BitLayout,
    Bits,
    FlightData,
    FlightDataCodec,
    decode_flight_data,
    encode_flight_data,
)
from adapters.wire.layout import Field, Layout

NEW_SIZES = [15, 16, 12, 13, 12, 50, 68, 44, 6, 12, 13, 4, 13, 2]
M100_SIZES = [9, 16, 12, 13, 12, 25, 6, 12, 13, 1, 1, 2]
FIRMWARES = ["new", "m100"]


def test_item_sizes_match_the_notes() -> None:
    assert [it.size for it in ITEMS["new"]] == NEW_SIZES
    assert [it.bit for it in ITEMS["new"]] == list(range(14))
    assert [it.size for it in ITEMS["m100"]] == M100_SIZES
    assert [it.bit for it in ITEMS["m100"]] == list(range(12))
    m100 = [it.name for it in ITEMS["m100"]]
    assert m100[6:] == ["mag", "rc", "gimbal", "status", "battery", "control_device"]


def test_hand_built_new_firmware_push() -> None:
    bitmap = 1 << 1 | 1 << 5 | 1 << 10 | 1 << 11 | 1 << 12 | 1 << 13
    lat, lon = 0.3926990816987, 2.0943951023932  # radians
    payload = (
        struct.pack("<H", bitmap)
        + struct.pack("<4f", 1.0, 0.0, 0.5, -0.5)
        + struct.pack("<ddffB", lat, lon, 120.5, 30.25, 5)
        + struct.pack("<6f", 100.0, 200.0, 300.0, 400.0, 500.0, 600.0)
        + bytes([0b00100101])  # down, right, up healthy
        + struct.pack("<3fB", 1.5, -30.0, 90.0, 0b101)  # pitch and yaw limit
        + bytes([2, 17, 1, 0])  # in air, SDK control
        + struct.pack("<IiiB", 4500, 15800, -12000, 77)
        + bytes([2, 0b10010])  # control mode 2, device serial (2), vrc on
    )
    fd = decode_flight_data(payload, "new")
    assert fd.bitmap == bitmap and fd.unknown == b""
    assert list(fd.items) == ["quaternion", "position", "gimbal", "status", "battery", "control_device"]
    assert fd.items["quaternion"] == {"w": 1.0, "x": 0.0, "y": 0.5, "z": -0.5}
    pos = fd.items["position"]
    assert (pos["latitude"], pos["longitude"]) == (lat, lon)  # f64 radians, latitude first
    assert (pos["altitude"], pos["height"], pos["health"]) == (120.5, 30.25, 5)
    assert (pos["obstacle_down"], pos["obstacle_up"]) == (100.0, 600.0)
    assert [pos[k] for k in ("down_health", "front_health", "right_health", "back_health")] == [1, 0, 1, 0]
    assert (pos["left_health"], pos["up_health"], pos["obstacle_reserved"]) == (0, 1, 0)
    assert fd.items["gimbal"] == {
        "roll": 1.5,
        "pitch": -30.0,
        "yaw": 90.0,
        "pitch_limit": 1,
        "roll_limit": 0,
        "yaw_limit": 1,
        "reserved": 0,
    }
    assert fd.items["status"] == {"flight": 2, "display_mode": 17, "gear": 1, "error": 0}
    assert fd.items["battery"] == {"capacity": 4500, "voltage": 15800, "current": -12000, "percentage": 77}
    assert fd.items["control_device"] == {
        "control_mode": 2,
        "device_status": 2,
        "flight_status": 0,
        "vrc_status": 1,
        "reserved": 0,
    }
    assert encode_flight_data(fd.items, "new") == payload


def test_hand_built_gps_and_rtk_items() -> None:
    gps = struct.pack(
        "<IIiii3f6f2I2H", 20240102, 123456, 1139000000, 225000000, 50000, 1, 2, 3, *range(6), 9, 4, 13, 77
    )
    rtk = struct.pack("<IIddf3fhBB", 20240102, 123456, 113.9, 22.5, 48.5, 0.1, 0.2, 0.3, -90, 50, 16)
    fd = decode_flight_data(struct.pack("<H", 1 << 6 | 1 << 7) + gps + rtk, "new")
    g, r = fd.items["gps"], fd.items["rtk"]
    assert (g["longitude"], g["latitude"], g["hfsl"]) == (
        1139000000,
        225000000,
        50000,
    )  # OSDK order: lon first
    assert (g["used_gps"], g["used_glonass"], g["num_sv"], g["gps_counter"]) == (9, 4, 13, 77)
    assert (r["longitude"], r["latitude"], r["yaw"]) == (113.9, 22.5, -90)
    assert (r["pos_health_flag"], r["yaw_health_flag"]) == (50, 16)


def test_hand_built_m100_push() -> None:
    bitmap = 1 << 0 | 1 << 3 | 1 << 9 | 1 << 10
    payload = (
        struct.pack("<H", bitmap)
        + struct.pack("<IIB", 4000, 99, 1)
        + struct.pack("<3fB", 1.0, 2.0, -0.5, 0b1_0101_1)  # health 1, sensor id 0b0101, reserved 0b1
        + bytes([3, 87])  # in air, 87 %
    )
    fd = decode_flight_data(payload, "m100")
    assert fd.items == {
        "timestamp": {"time": 4000, "nano_time": 99, "sync_flag": 1},
        "velocity": {"x": 1.0, "y": 2.0, "z": -0.5, "health": 1, "sensor_id": 0b0101, "reserved": 1},
        "status": {"flight": 3},
        "battery": {"percentage": 87},
    }
    assert encode_flight_data(fd.items, "m100") == payload
    # under the new layout the same bitmap announces 15 + 13 + 12 + 13 bytes, more than sent: an error
    with pytest.raises(LayoutError):
        decode_flight_data(payload, "new")


@pytest.mark.parametrize("firmware", FIRMWARES)
def test_every_bit_round_trips(firmware: str) -> None:
    for it in ITEMS[firmware]:
        payload = encode_flight_data({it.name: it.codec.example()}, firmware)
        assert len(payload) == 2 + it.size
        assert int.from_bytes(payload[:2], "little") == 1 << it.bit
        assert decode_flight_data(payload, firmware) == FlightData(
            firmware, 1 << it.bit, {it.name: it.codec.example()}
        )


def _field_strategy(f: Field) -> st.SearchStrategy[Any]:
    if f.code == "f":
        one: st.SearchStrategy[Any] = st.floats(width=32, allow_nan=False, allow_infinity=False)
    elif f.code == "d":
        one = st.floats(allow_nan=False, allow_infinity=False)
    elif f.code == "s":
        return st.binary(min_size=f.count, max_size=f.count)
    else:
        bits = struct.calcsize(f.code) * 8
        lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if f.code.islower() else (0, (1 << bits) - 1)
        one = st.integers(lo, hi)
    return st.lists(one, min_size=f.count, max_size=f.count) if f.count > 1 else one


def _codec_strategy(codec: Layout | BitLayout) -> st.SearchStrategy[dict[str, Any]]:
    layout = codec.layout if isinstance(codec, BitLayout) else codec
    bits: dict[str, Bits] = {b.field: b for b in codec.bits} if isinstance(codec, BitLayout) else {}
    parts: dict[str, st.SearchStrategy[Any]] = {}
    for f in layout.fields:
        if f.name in bits:
            for name, width in bits[f.name].parts:
                parts[name] = st.integers(0, (1 << width) - 1)
        else:
            parts[f.name] = _field_strategy(f)
    return st.fixed_dictionaries(parts)


@st.composite
def _push(draw: st.DrawFn, firmware: str) -> dict[str, dict[str, Any]]:
    bitmap = draw(st.integers(0, (1 << len(ITEMS[firmware])) - 1))
    return {it.name: draw(_codec_strategy(it.codec)) for it in ITEMS[firmware] if bitmap >> it.bit & 1}


@pytest.mark.parametrize("firmware", FIRMWARES)
@given(data=st.data())
def test_random_bitmaps_round_trip(firmware: str, data: st.DataObject) -> None:
    items = data.draw(_push(firmware))
    payload = encode_flight_data(items, firmware)
    sizes = {it.name: it.size for it in ITEMS[firmware]}
    assert len(payload) == 2 + sum(sizes[n] for n in items)
    fd = decode_flight_data(payload, firmware)
    assert list(fd.items) == [it.name for it in ITEMS[firmware] if it.name in items]  # bit order
    assert fd.items == items
    assert encode_flight_data(fd.items, firmware) == payload


@pytest.mark.parametrize("firmware", FIRMWARES)
@given(data=st.binary(max_size=300))
def test_random_payloads_raise_only_layout_errors(firmware: str, data: bytes) -> None:
    try:
        fd = decode_flight_data(data, firmware)
    except LayoutError:
        return
    again = encode_flight_data(
        fd.items, firmware, unknown_bits=fd.bitmap & ~_known(firmware), unknown=fd.unknown
    )
    assert again == data


def _known(firmware: str) -> int:
    return sum(1 << it.bit for it in ITEMS[firmware])


def test_unknown_bits_keep_their_bytes() -> None:
    payload = encode_flight_data(
        {"status": {"flight": 2}}, "new", unknown_bits=1 << 15, unknown=b"\x01\x02\x03"
    )
    fd = decode_flight_data(payload, "new")
    assert fd.bitmap == 1 << 11 | 1 << 15
    assert fd.unknown == b"\x01\x02\x03"
    assert fd.items["status"]["flight"] == 2
    codec = FlightDataCodec("new")
    decoded = codec.decode(payload)
    assert decoded["unknown"] == b"\x01\x02\x03"
    assert codec.encode(decoded) == payload


def test_length_errors_are_clear() -> None:
    with pytest.raises(LayoutError, match="2-byte bitmap"):
        decode_flight_data(b"\x01", "new")
    with pytest.raises(LayoutError, match=r"announces quaternion \(bit 1, 16 bytes\)"):
        decode_flight_data(struct.pack("<H", 2) + bytes(15), "new")
    with pytest.raises(LayoutError, match="1 bytes after the items"):
        decode_flight_data(struct.pack("<H", 2) + bytes(17), "new")
    with pytest.raises(LayoutError, match="unknown flight data item"):
        encode_flight_data({"gps": {}}, "m100")
    with pytest.raises(LayoutError, match="overlaps"):
        encode_flight_data({}, "new", unknown_bits=1)
    with pytest.raises(LayoutError, match="does not match"):
        FlightDataCodec("new").encode({"bitmap": 1, "quaternion": {}})
    with pytest.raises(LayoutError, match="does not fit 1 bit"):
        encode_flight_data({"velocity": {"health": 2}}, "new")
    with pytest.raises(ValueError, match="firmware"):
        decode_flight_data(b"\0\0", "m600")


def test_bit_layout_rejects_bad_declarations() -> None:
    with pytest.raises(ValueError, match="cover 7 of 8"):
        BitLayout((Field("a", "B"),), (Bits("a", (("x", 7),)),))
    with pytest.raises(ValueError, match="unsigned scalar"):
        BitLayout((Field("a", "f"),), (Bits("a", (("x", 32),)),))
    with pytest.raises(ValueError, match="duplicate"):
        BitLayout((Field("a", "B"), Field("x", "B")), (Bits("a", (("x", 8),)),))


def test_flight_data_push_through_frame_and_table() -> None:
    items = {
        "quaternion": {"w": 1.0, "x": 0.0, "y": 0.0, "z": 0.0},
        "position": {"latitude": math.radians(22.5), "longitude": math.radians(113.9), "health": 4},
    }
    for firmware in FIRMWARES:
        frame = decode_frame(encode_command(0x02, 0x00, encode_flight_data(items, firmware), 0, 5))
        assert frame.cmd_set is not None and frame.cmd_id is not None
        msg = decode_request(frame.cmd_set, frame.cmd_id, frame.payload, firmware)
        assert msg.name == "flight_data_push"
        assert msg.fields["bitmap"] == 0b100010
        assert msg.fields["position"]["latitude"] == math.radians(22.5)
        assert msg.fields["quaternion"]["w"] == 1.0


@pytest.mark.parametrize("firmware", FIRMWARES)
def test_codec_examples_round_trip(firmware: str) -> None:
    codec = FlightDataCodec(firmware)
    examples = codec.examples()
    assert len(examples) == len(ITEMS[firmware]) + 2
    for ex in examples:
        assert codec.decode(codec.encode(ex)) == ex
