"""The 0xA5 "DJI serial" frame (seed 002): the seed's "hello" vector, the CRC parameters, and the
stream decoder under splits, garbage and random input."""

from __future__ import annotations

import itertools

import pytest
from crc import Calculator, Configuration, Crc8, Crc16
from hypothesis import given
from hypothesis import strategies as st

from adapters.robomaster.protocol import (
    DEFAULT_MAX_DATA_LEN,
    REFEREE_MAX_DATA_LEN,
    REFEREE_MAX_FRAME_LEN,
    SOF,
    BadFrame,
    Decoder,
    Frame,
    encode_frame,
)
from adapters.wire.crc import crc8_rm, crc16_rm

# Seed 002, "Example": the exact bytes the guide prints for b"hello", cmd 0, seq 0.
HELLO = bytes.fromhex("A5 05 00 00 F6 00 00 68 65 6C 6C 6F 56 34")
HELLO_FRAME = Frame(seq=0, cmd_id=0, data=b"hello")

# The seed's own crc-package configurations (named "MAXIM_DOW" and "KERMIT" there, wrongly).
SEED_RM_CRC8 = Configuration(
    width=8, polynomial=0x31, init_value=0xFF, final_xor_value=0, reverse_input=True, reverse_output=True
)
SEED_RM_CRC16 = Configuration(
    width=16, polynomial=0x1021, init_value=0xFFFF, final_xor_value=0, reverse_input=True, reverse_output=True
)


def frames_of(events: list[Frame | BadFrame]) -> list[Frame]:
    return [e for e in events if isinstance(e, Frame)]


def run(
    chunks: list[bytes], max_data_len: int = DEFAULT_MAX_DATA_LEN
) -> tuple[list[Frame | BadFrame], Decoder]:
    dec = Decoder(max_data_len)
    out: list[Frame | BadFrame] = []
    for chunk in chunks:
        out += dec.feed(chunk)
    out += dec.flush()
    return out, dec


def is_subsequence(needle: list[Frame], hay: list[Frame]) -> bool:
    it = iter(hay)
    return all(any(x == y for y in it) for x in needle)


# --------------------------------------------------------------------------- vectors and CRCs


def test_hello_frame_is_reproduced_exactly() -> None:
    assert encode_frame(0x0000, b"hello", seq=0) == HELLO


def test_hello_header_and_frame_crcs_match_the_seed() -> None:
    assert crc8_rm(HELLO[:4]) == 0xF6
    assert crc16_rm(HELLO[:-2]) == 0x3456  # sent LSB first: 56 34


def test_crc_check_values() -> None:
    assert crc8_rm(b"123456789") == 0x0B
    assert crc16_rm(b"123456789") == 0x6F91


def test_the_named_standard_crcs_are_not_what_the_link_uses() -> None:
    # CRC-8/MAXIM-DOW and KERMIT start at 0: the seed's names are wrong, its parameters right.
    assert Calculator(Crc8.MAXIM_DOW).checksum(b"123456789") != crc8_rm(b"123456789")
    assert Calculator(Crc16.KERMIT).checksum(b"123456789") != crc16_rm(b"123456789")


@given(st.binary(max_size=300))
def test_our_crcs_equal_the_seeds_configurations(data: bytes) -> None:
    assert crc8_rm(data) == Calculator(SEED_RM_CRC8).checksum(data)
    assert crc16_rm(data) == Calculator(SEED_RM_CRC16).checksum(data)


def test_encode_frame_layout() -> None:
    raw = encode_frame(0x0203, bytes(range(12)), seq=0x7F)
    assert raw[0] == SOF
    assert raw[1:3] == (12).to_bytes(2, "little")
    assert raw[3] == 0x7F
    assert raw[4] == crc8_rm(raw[:4])
    assert raw[5:7] == b"\x03\x02"
    assert raw[7:-2] == bytes(range(12))
    assert raw[-2:] == crc16_rm(raw[:-2]).to_bytes(2, "little")


@pytest.mark.parametrize(
    ("cmd_id", "data", "seq"),
    [(-1, b"", 0), (0x10000, b"", 0), (1, b"", -1), (1, b"", 256), (1, bytes(0x10000), 0)],
)
def test_encode_frame_rejects_out_of_range(cmd_id: int, data: bytes, seq: int) -> None:
    with pytest.raises(ValueError):
        encode_frame(cmd_id, data, seq)


def test_decoder_bound_must_fit_the_length_field() -> None:
    with pytest.raises(ValueError):
        Decoder(0x10000)


# --------------------------------------------------------------------------- the hello vector, every way


def test_hello_fed_whole() -> None:
    out, dec = run([HELLO])
    assert out == [HELLO_FRAME]
    assert dec.stats.frames == 1 and dec.pending == 0


def test_hello_fed_byte_by_byte() -> None:
    dec = Decoder()
    out: list[Frame | BadFrame] = []
    for i in range(len(HELLO)):
        got = dec.feed(HELLO[i : i + 1])
        assert got == ([] if i < len(HELLO) - 1 else [HELLO_FRAME])
        out += got
    assert out == [HELLO_FRAME] and dec.flush() == []


@pytest.mark.parametrize("cut", range(len(HELLO) + 1))
def test_hello_split_at_every_offset(cut: int) -> None:
    out, _ = run([HELLO[:cut], HELLO[cut:]])
    assert out == [HELLO_FRAME]


@pytest.mark.parametrize(
    "garbage",
    [
        b"\x00\x01\x02",
        b"\xa5",  # a lone SOF
        b"\xa5\xa5\xa5",
        b"\xa5\x05\x00\x00\x00",  # a header with a bad CRC8
        HELLO[:9],  # the start of a frame that never finishes
        b"\xa5\x05\x00\x00\xf6\x00\x00hel",  # a good header, then too few bytes
    ],
)
def test_hello_after_garbage(garbage: bytes) -> None:
    out, _ = run([garbage + HELLO + HELLO])
    assert frames_of(out) == [HELLO_FRAME, HELLO_FRAME]
    assert b"".join(e.raw for e in out if isinstance(e, BadFrame)) == garbage


def test_header_crc_failure_is_reported_and_skipped() -> None:
    bad = bytearray(HELLO)
    bad[4] ^= 0xFF
    out, _ = run([bytes(bad) + HELLO])
    assert frames_of(out) == [HELLO_FRAME]
    assert [e.reason for e in out if isinstance(e, BadFrame)] == ["header crc"]


def test_frame_crc_failure_is_reported_and_skipped() -> None:
    bad = bytearray(HELLO)
    bad[8] ^= 0x01  # body bit flip
    out, _ = run([bytes(bad) + HELLO])
    assert frames_of(out) == [HELLO_FRAME]
    assert [e.reason for e in out if isinstance(e, BadFrame)] == ["frame crc"]


def test_zero_length_body() -> None:
    raw = encode_frame(0x0F01, b"", seq=9)
    assert len(raw) == 9
    assert run([raw])[0] == [Frame(9, 0x0F01, b"")]


def test_referee_preset_drops_an_oversized_header_at_once() -> None:
    big = encode_frame(0x0301, bytes(REFEREE_MAX_DATA_LEN + 1))
    fits = encode_frame(0x0301, bytes(REFEREE_MAX_DATA_LEN))
    assert len(fits) == REFEREE_MAX_FRAME_LEN
    dec = Decoder(REFEREE_MAX_DATA_LEN)
    # no flush needed: the too-long header is refused before its body arrives
    out = dec.feed(big[:5] + HELLO)
    assert frames_of(out) == [HELLO_FRAME]
    assert [e.reason for e in out if isinstance(e, BadFrame)] == ["data too long"]
    assert frames_of(dec.feed(fits)) == [Frame(0, 0x0301, bytes(REFEREE_MAX_DATA_LEN))]


def test_default_decoder_accepts_taproot_sized_frames() -> None:
    raw = encode_frame(0x0001, bytes(range(256)) * 4, seq=1)
    assert run([raw])[0] == [Frame(1, 0x0001, bytes(range(256)) * 4)]
    too_big = encode_frame(0x0001, bytes(DEFAULT_MAX_DATA_LEN + 1))
    out, _ = run([too_big])
    assert out == [BadFrame("data too long", too_big)]  # no later SOF: every byte goes with it


def test_a_false_long_header_is_released_by_flush() -> None:
    # a valid-CRC8 header announcing 1000 bytes hides the real frame until the line goes idle
    head = bytearray((SOF, 1000 & 0xFF, 1000 >> 8, 0))
    head.append(crc8_rm(head))
    dec = Decoder()
    assert frames_of(dec.feed(bytes(head) + HELLO)) == []
    assert frames_of(dec.flush()) == [HELLO_FRAME]
    assert dec.pending == 0


# --------------------------------------------------------------------------- properties

frame_st = st.builds(
    Frame,
    seq=st.integers(0, 255),
    cmd_id=st.integers(0, 0xFFFF),
    data=st.binary(max_size=140),
)


def chunked(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts})
    edges = [0, *points, len(data)]
    return [data[a:b] for a, b in itertools.pairwise(edges)]


@given(st.binary(max_size=600), st.lists(st.integers(0, 10_000), max_size=8))
def test_random_bytes_never_raise_never_stall_and_lose_no_byte(data: bytes, cuts: list[int]) -> None:
    out, dec = run(chunked(data, cuts))
    assert dec.pending == 0
    used = sum(len(e.raw) for e in out if isinstance(e, BadFrame))
    used += sum(9 + len(e.data) for e in out if isinstance(e, Frame))
    assert used == len(data)


@given(st.binary(max_size=600))
def test_random_bytes_with_referee_bound(data: bytes) -> None:
    out, dec = run([data], REFEREE_MAX_DATA_LEN)
    assert dec.pending == 0
    assert all(len(e.data) <= REFEREE_MAX_DATA_LEN for e in frames_of(out))


@given(st.lists(frame_st, max_size=6), st.lists(st.integers(0, 10_000), max_size=10))
def test_random_frames_round_trip_through_any_chunking(frames: list[Frame], cuts: list[int]) -> None:
    wire = b"".join(encode_frame(f.cmd_id, f.data, f.seq) for f in frames)
    out, _ = run(chunked(wire, cuts))
    assert out == frames


@given(st.lists(st.tuples(st.binary(max_size=40), frame_st), min_size=1, max_size=5), st.binary(max_size=40))
def test_every_valid_frame_after_garbage_is_found(pairs: list[tuple[bytes, Frame]], tail: bytes) -> None:
    wire = b"".join(g + encode_frame(f.cmd_id, f.data, f.seq) for g, f in pairs) + tail
    out, dec = run([wire])
    assert is_subsequence([f for _, f in pairs], frames_of(out))
    assert dec.pending == 0
