"""The shared DJI R SDK / OSDK frame envelope: fast CRC16 table, header pack/read/validate, CRC32."""

from __future__ import annotations

import struct

import crc
import pytest
from hypothesis import given
from hypothesis import strategies as st

from adapters.osdk import protocol as osdk
from adapters.rsdk import protocol as rsdk
from adapters.wire.crc import crc16_rsdk, crc32_rsdk
from adapters.wire.dji_frame import (
    BAD_HEADER_CRC,
    BAD_RESERVED,
    BAD_SOF,
    BAD_VERSION,
    CRC16_T16,
    HEADER_LEN,
    SHORT_HEADER,
    TOO_SHORT,
    Header,
    HeaderRules,
    build_frame,
    crc16_fast,
    crc32_ok,
    header_crc16,
    header_crc_ok,
    pack_header,
    read_header,
    seal_crc32,
)
from adapters.wire.stream import BadFrame, StreamDecoder

# Seed 000 §3.3 Figure 41 (R SDK position control, seq 0x1122): header CRC16 0x42A2, CRC32 0xBE97407B.
SAMPLE = bytes.fromhex("AA 1A 00 03 00 00 00 00 22 11 A2 42 0E 00 20 00 30 00 40 00 01 14 7B 40 97 BE")
# OSDK header-only ACK, session 3, seq 1 (tests/test_osdk_protocol.py, checked there with pycrc).
HEADER_ONLY = bytes.fromhex("aa 0c 00 23 00 00 00 00 01 00 bc dc")

# Independent oracles: the seed's pycrc models (init written unreflected), not our engines.
C16 = crc.Calculator(crc.Configuration(16, 0x8005, 0xC55C, 0, reverse_input=True, reverse_output=True))
C32 = crc.Calculator(
    crc.Configuration(32, 0x04C11DB7, 0xC55C0000, 0, reverse_input=True, reverse_output=True)
)

RSDK_LIKE = HeaderRules(min_len=18, min_flagged_len=17, header_only=False, reserved_zero=False)
OSDK_LIKE = HeaderRules(min_len=16, header_only=True, reserved_zero=True)


def _header(word: int, b3: int = 0x03, enc: int = 0, reserved: bytes = b"\0\0\0", seq: int = 1) -> bytes:
    """A header with a correct CRC16 whatever the fields say."""
    h = bytes([0xAA]) + word.to_bytes(2, "little") + bytes([b3, enc]) + reserved + seq.to_bytes(2, "little")
    return h + C16.checksum(h).to_bytes(2, "little")


# --- CRC16 ---------------------------------------------------------------------------------------


def test_crc16_check_values() -> None:
    assert crc16_fast(b"123456789") == 0x2752
    assert header_crc16(SAMPLE) == 0x42A2
    assert header_crc_ok(SAMPLE[:12]) and header_crc_ok(HEADER_ONLY)


def test_crc16_word_table_is_the_shared_engine_over_two_bytes() -> None:
    """Every entry of the 65536-entry table, against the byte-wise engine from a zero register."""
    assert len(CRC16_T16) == 0x10000
    bad = [w for w in range(0x10000) if CRC16_T16[w] != crc16_rsdk(w.to_bytes(2, "little"), 0)]
    assert bad == []


@given(st.binary(max_size=64), st.integers(0, 0xFFFF))
def test_fast_crc16_matches_shared_engine(data: bytes, seed: int) -> None:
    assert crc16_fast(data) == crc16_rsdk(data)
    assert crc16_fast(data, seed) == crc16_rsdk(data, seed)
    assert crc16_fast(bytearray(data)) == crc16_fast(memoryview(data)) == crc16_rsdk(data)


@given(st.binary(min_size=10, max_size=10), st.integers(0, 0xFFFF))
def test_header_crc_ok_exactly_when_stored_crc_matches(head10: bytes, stored: int) -> None:
    assert header_crc16(head10) == C16.checksum(head10)
    good = head10 + C16.checksum(head10).to_bytes(2, "little")
    assert header_crc_ok(good)
    other = head10 + stored.to_bytes(2, "little")
    assert header_crc_ok(other) == (other == good)


@pytest.mark.parametrize("bit", range(96))
def test_any_single_bit_flip_in_the_header_fails_its_crc(bit: int) -> None:
    h = bytearray(SAMPLE[:12])
    h[bit // 8] ^= 1 << (bit % 8)
    assert not header_crc_ok(h)


# --- CRC32 ---------------------------------------------------------------------------------------


def test_crc32_seed_sample() -> None:
    assert crc32_ok(SAMPLE)
    buf = bytearray(SAMPLE[:-4] + b"\0\0\0\0")
    seal_crc32(buf)
    assert bytes(buf) == SAMPLE and buf[-4:] == (0xBE97407B).to_bytes(4, "little")


@given(st.binary(min_size=1, max_size=80), st.binary(min_size=4, max_size=4))
def test_crc32_ok_exactly_when_trailer_matches(data: bytes, trailer: bytes) -> None:
    good = C32.checksum(data).to_bytes(4, "little")
    assert crc32_rsdk(data).to_bytes(4, "little") == good
    assert crc32_ok(data + good)
    assert crc32_ok(data + trailer) == (trailer == good)
    buf = bytearray(data + trailer)
    seal_crc32(buf)
    assert bytes(buf) == data + good


# --- header pack / read --------------------------------------------------------------------------


def test_pack_header_seed_sample() -> None:
    buf = bytearray(len(SAMPLE))
    pack_header(buf, len(SAMPLE), 0x03, 0, 0x1122)
    assert bytes(buf[:12]) == SAMPLE[:12]
    assert bytes(buf[12:]) == bytes(len(SAMPLE) - 12)  # nothing written past the header


def test_pack_header_rejects_out_of_range_fields() -> None:
    with pytest.raises(struct.error):
        pack_header(bytearray(12), 12, 0x100, 0, 0)
    with pytest.raises(struct.error):
        pack_header(bytearray(12), 12, 0, 0, 0x10000)


def test_build_frame_vectors() -> None:
    assert build_frame(0x03, 0, 0x1122, SAMPLE[12:-4]) == SAMPLE
    assert build_frame(0x23, 0, 1, b"") == HEADER_ONLY  # no data: header only, no CRC32


def test_read_header() -> None:
    assert read_header(SAMPLE) == Header(length=26, version=0, type_bits=3, flag=False, enc=0, seq=0x1122)
    assert read_header(HEADER_ONLY) == Header(12, 0, 3, True, 0, 1)
    assert read_header(_header(0x0412, b3=0xFF, enc=0xE5, seq=0xBEEF)) == Header(
        0x12, 1, 0x1F, True, 0xE5, 0xBEEF
    )


@given(st.integers(0, 0x3F), st.integers(0, 0xFF), st.integers(0, 0xFFFF), st.binary(max_size=200))
def test_build_read_round_trip(type_byte: int, enc: int, seq: int, data: bytes) -> None:
    raw = build_frame(type_byte, enc, seq, data)
    n = len(raw)
    assert n == (HEADER_LEN if not data else HEADER_LEN + len(data) + 4)
    assert raw[:10] + C16.checksum(raw[:10]).to_bytes(2, "little") == raw[:12]
    assert raw[5:8] == b"\0\0\0"
    if data:
        assert raw[12:-4] == data and raw[-4:] == C32.checksum(raw[:-4]).to_bytes(4, "little")
    expected = Header(n, 0, type_byte & 0x1F, bool(type_byte & 0x20), enc, seq)
    assert read_header(raw) == expected
    assert OSDK_LIKE.parse_header(raw) == expected
    assert RSDK_LIKE.frame_length(raw[:12]) == (n if n >= 18 or (n == 17 and type_byte & 0x20) else TOO_SHORT)


def test_both_adapters_build_the_same_bytes() -> None:
    assert rsdk.encode_frame(0x0E, 0x00, SAMPLE[14:-4], 0x1122) == SAMPLE
    assert osdk.encode_command(0x0E, 0x00, SAMPLE[14:-4], 3, 0x1122) == SAMPLE
    assert rsdk.crc16_fast is crc16_fast  # the R SDK's public name is the shared engine


# --- header validation ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("rules", "header", "expected"),
    [
        (RSDK_LIKE, SAMPLE[:12], 26),
        (OSDK_LIKE, SAMPLE[:12], 26),
        (RSDK_LIKE, _header(26 | 1 << 10), BAD_VERSION),
        (OSDK_LIKE, _header(26 | 1 << 10), BAD_VERSION),
        # minimum lengths: unflagged vs flagged (bit 5)
        (RSDK_LIKE, _header(18, b3=0x03), 18),
        (RSDK_LIKE, _header(17, b3=0x03), TOO_SHORT),
        (RSDK_LIKE, _header(17, b3=0x20), 17),
        (RSDK_LIKE, _header(16, b3=0x20), TOO_SHORT),
        (OSDK_LIKE, _header(16, b3=0x03), 16),
        (OSDK_LIKE, _header(15, b3=0x23), TOO_SHORT),
        # header-only frames
        (OSDK_LIKE, _header(12, b3=0x23), 12),
        (OSDK_LIKE, _header(12, b3=0x03), 12),  # the header allows it; the adapter's parse decides
        (RSDK_LIKE, _header(12, b3=0x23), TOO_SHORT),
        (OSDK_LIKE, _header(13), TOO_SHORT),
        (OSDK_LIKE, _header(11), TOO_SHORT),
        # reserved bits 7:6 of byte 3 and bytes 5..7
        (OSDK_LIKE, _header(26, b3=0x43), BAD_RESERVED),
        (OSDK_LIKE, _header(26, b3=0x83), BAD_RESERVED),
        (OSDK_LIKE, _header(26, reserved=b"\x01\0\0"), BAD_RESERVED),
        (OSDK_LIKE, _header(26, reserved=b"\0\x01\0"), BAD_RESERVED),
        (OSDK_LIKE, _header(26, reserved=b"\0\0\x80"), BAD_RESERVED),
        (RSDK_LIKE, _header(26, b3=0xC3, reserved=b"\xff\xff\xff"), 26),
        # CRC last: a bad CRC is only reported for an otherwise plausible header
        (RSDK_LIKE, SAMPLE[:10] + b"\0\0", BAD_HEADER_CRC),
        (OSDK_LIKE, SAMPLE[:10] + b"\0\0", BAD_HEADER_CRC),
        (RSDK_LIKE, b"\xaa\xff\xff" + bytes(9), BAD_VERSION),
        (OSDK_LIKE, b"\xaa\x1a\x00\x03\x00\x01" + bytes(6), BAD_RESERVED),
        (RSDK_LIKE, b"\xaa\x05\x00" + bytes(9), TOO_SHORT),
    ],
)
def test_frame_length(rules: HeaderRules, header: bytes, expected: int | str) -> None:
    assert rules.frame_length(header) == expected


def test_parse_header() -> None:
    assert RSDK_LIKE.parse_header(SAMPLE) == read_header(SAMPLE)
    assert RSDK_LIKE.parse_header(SAMPLE[:11]) == SHORT_HEADER
    assert RSDK_LIKE.parse_header(b"\x55" + SAMPLE[1:]) == BAD_SOF
    assert OSDK_LIKE.parse_header(bytearray(HEADER_ONLY)) == Header(12, 0, 3, True, 0, 1)
    assert RSDK_LIKE.parse_header(HEADER_ONLY) == TOO_SHORT


def test_default_flagged_minimum_is_the_minimum() -> None:
    rules = HeaderRules(min_len=20, header_only=False, reserved_zero=False)
    assert rules.min_flagged_len == 20
    assert rules.frame_length(_header(19, b3=0x20)) == TOO_SHORT
    assert rules.frame_length(_header(20, b3=0x20)) == 20


# --- in a stream decoder -------------------------------------------------------------------------


class _RawRules(HeaderRules):
    """The envelope alone: a frame is its bytes once the CRC32 (if any) holds."""

    __slots__ = ()

    def __init__(self) -> None:
        super().__init__(min_len=16, header_only=True, reserved_zero=True)

    def parse(self, frame: bytes) -> bytes | str:
        return frame if len(frame) == HEADER_LEN or crc32_ok(frame) else "frame crc"


frame_st = st.builds(
    build_frame, st.integers(0, 0x3F), st.integers(0, 0xFF), st.integers(0, 0xFFFF), st.binary(max_size=60)
)


def _decode(data: bytes, chunk: int) -> list[bytes | BadFrame]:
    dec: StreamDecoder[bytes] = StreamDecoder(_RawRules())
    out: list[bytes | BadFrame] = []
    for i in range(0, len(data), chunk):
        out += dec.feed(data[i : i + chunk])
    out += dec.flush()
    assert dec.pending == 0
    return out


@given(st.lists(st.tuples(st.binary(max_size=30), frame_st), max_size=5), st.integers(1, 40))
def test_frames_after_garbage_are_found(parts: list[tuple[bytes, bytes]], chunk: int) -> None:
    stream = b"".join(g + f for g, f in parts)
    out = _decode(stream, chunk)
    # garbage may by chance hold a valid header-only frame, so look for ours in order
    found = iter([i for i in out if not isinstance(i, BadFrame)])
    assert all(any(got == f for got in found) for _, f in parts)
    assert sum(len(i) if isinstance(i, bytes) else len(i.raw) for i in out) == len(stream)


@given(st.binary(max_size=400), st.integers(1, 64))
def test_random_bytes_never_raise_nor_stall(data: bytes, chunk: int) -> None:
    out = _decode(data, chunk)
    assert sum(len(i) if isinstance(i, bytes) else len(i.raw) for i in out) == len(data)
