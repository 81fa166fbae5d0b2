"""adapters.wire.bits (shared C bit-field codec) and adapters.wire.describe_util: LSB-first layout
against hand-packed bytes, declaration checks, value range checks, round trips."""

from __future__ import annotations

import struct
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from adapters.wire.bits import BitLayout, Bits
from adapters.wire.describe_util import check_options, jsonable
from adapters.wire.layout import Field, LayoutError

# u8 head, u8 {a : 1, b : 3, c : 4}, u16 {lo : 5, hi : 11}
CODEC = BitLayout(
    (Field("head", "B"), Field("flags", "B"), Field("word", "H")),
    (Bits("flags", (("a", 1), ("b", 3), ("c", 4))), Bits("word", (("lo", 5), ("hi", 11)))),
)


def test_parts_are_allocated_lsb_first_like_a_c_compiler() -> None:
    # a=1 -> bit 0; b=0b101 -> bits 1..3; c=0b1001 -> bits 4..7  =>  0b1001_101_1 = 0x9B
    # lo=0b10011 -> bits 0..4; hi=0x5A5 -> bits 5..15          =>  0x5A5 << 5 | 0x13 = 0xB4B3
    values = {"head": 7, "a": 1, "b": 0b101, "c": 0b1001, "lo": 0b10011, "hi": 0x5A5}
    raw = bytes([7, 0b1001_101_1]) + struct.pack("<H", 0x5A5 << 5 | 0b10011)
    assert raw == bytes([0x07, 0x9B, 0xB3, 0xB4])
    assert CODEC.encode(values) == raw
    assert CODEC.decode(raw) == values


def test_names_replace_the_carrier_in_struct_order() -> None:
    assert CODEC.field_names == ["head", "a", "b", "c", "lo", "hi"]
    assert CODEC.names == CODEC.field_names
    assert list(CODEC.decode(bytes(4))) == CODEC.field_names
    assert CODEC.size == 4
    assert CODEC.bits[0] == Bits("flags", (("a", 1), ("b", 3), ("c", 4)))


def test_example_sets_every_part_non_zero_and_round_trips() -> None:
    ex = CODEC.example()
    assert (ex["a"], ex["b"], ex["c"], ex["lo"], ex["hi"]) == (1, 2, 3, 1, 2)
    assert CODEC.decode(CODEC.encode(ex)) == ex


def test_missing_parts_default_to_zero_and_bools_are_bits() -> None:
    assert CODEC.encode({"a": True}) == bytes([0, 1, 0, 0])


@given(st.binary(min_size=4, max_size=4))
def test_any_payload_survives_decode_encode(raw: bytes) -> None:
    assert CODEC.encode(CODEC.decode(raw)) == raw


@pytest.mark.parametrize(
    ("part", "bad"), [("a", 2), ("b", 8), ("c", -1), ("hi", 1 << 11), ("lo", 1.0), ("b", "1")]
)
def test_values_that_do_not_fit_their_width_are_rejected(part: str, bad: Any) -> None:
    with pytest.raises(LayoutError, match=f"{part}: .* does not fit"):
        CODEC.encode({part: bad})


def test_unknown_fields_and_the_carrier_name_are_rejected() -> None:
    with pytest.raises(LayoutError, match=r"unknown field\(s\) \['flags'\]"):
        CODEC.encode({"flags": 1})
    with pytest.raises(LayoutError, match="unknown field"):
        CODEC.encode({"d": 1})


@pytest.mark.parametrize(
    ("fields", "bits", "match"),
    [
        ((Field("w", "B"),), (Bits("w", (("x", 7),)),), "add up to 8.*cover 7 of 8"),
        ((Field("w", "H"),), (Bits("w", (("x", 8), ("y", 9))),), "cover 17 of 16"),
        ((Field("w", "B"),), (Bits("w", (("x", 8), ("y", 0))),), "each >= 1"),
        ((Field("w", "f"),), (Bits("w", (("x", 32),)),), "unsigned integer"),
        ((Field("w", "b"),), (Bits("w", (("x", 8),)),), "unsigned"),
        ((Field("w", "B", count=2),), (Bits("w", (("x", 8),)),), "unsigned scalar"),
        ((Field("w", "B"),), (Bits("v", (("x", 8),)),), "v: bit fields need"),
        ((Field("w", "B"),), (Bits("w", (("x", 8),)), Bits("w", (("y", 8),))), "declared twice"),
        ((Field("a", "B"), Field("w", "B")), (Bits("w", (("a", 8),)),), "duplicate"),
    ],
)
def test_bad_declarations_fail_at_construction(
    fields: tuple[Field, ...], bits: tuple[Bits, ...], match: str
) -> None:
    with pytest.raises(ValueError, match=match):
        BitLayout(fields, bits)


def test_a_64_bit_word_splits_too() -> None:
    codec = BitLayout((Field("q", "Q"),), (Bits("q", (("low", 1), ("high", 63))),))
    assert codec.encode({"low": 1, "high": (1 << 63) - 1}) == b"\xff" * 8
    assert codec.decode(b"\x02" + bytes(7)) == {"low": 0, "high": 1}


def test_check_options_names_unknown_and_valid_options() -> None:
    check_options({"season": "2026"}, ("season", "max_data_len"), "robomaster")
    with pytest.raises(
        ValueError, match=r"unknown option\(s\) \['sesaon'\] for robomaster; valid: max_data_len, season"
    ):
        check_options({"sesaon": 1}, ("season", "max_data_len"), "robomaster")


def test_jsonable_turns_bytes_into_hex_recursively() -> None:
    value = {"a": b"\x01\xff", "b": [bytearray(b"\x02"), (1, 2.5)], "c": {"d": None, "e": "x"}}
    assert jsonable(value) == {"a": "01ff", "b": ["02", [1, 2.5]], "c": {"d": None, "e": "x"}}
