"""R SDK frame layer: the seed §3.3 vector, CRCs, header checks, resync and never-stall properties."""

from __future__ import annotations

import ast
import pathlib
import sys
import zlib

import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from adapters.rsdk.protocol import (
    MAX_FRAME_LEN,
    BadFrame,
    Decoder,
    Frame,
    FrameRules,
    crc16_fast,
    encode,
    encode_frame,
)
from adapters.wire.crc import crc16_rsdk, crc32_rsdk

# Seed 000 §3.3 Figure 41: position control, seq 0x1122 (little-endian on the wire).
SAMPLE = bytes.fromhex("AA 1A 00 03 00 00 00 00 22 11 A2 42 0E 00 20 00 30 00 40 00 01 14 7B 40 97 BE")
SAMPLE_FRAME = Frame(0x0E, 0x00, bytes.fromhex("2000300040000114"), seq=0x1122, cmd_type=3)


def frames_of(items: list) -> list[Frame]:
    return [i for i in items if isinstance(i, Frame)]


def decode_all(data: bytes, chunk: int | None = None) -> list:
    d = Decoder()
    out: list = []
    if chunk is None:
        out += d.feed(data)
    else:
        for i in range(0, len(data), chunk):
            out += d.feed(data[i : i + chunk])
    out += d.flush()
    assert d.pending == 0
    return out


# --- the seed vector -----------------------------------------------------------------------------


def test_seed_sample_encodes_exactly() -> None:
    assert encode(SAMPLE_FRAME) == SAMPLE
    assert encode_frame(0x0E, 0x00, bytes.fromhex("2000300040000114"), 0x1122) == SAMPLE


def test_seed_sample_fields() -> None:
    assert SAMPLE[1] | SAMPLE[2] << 8 == len(SAMPLE) == 26
    assert SAMPLE[8:10] == b"\x22\x11"  # seq 0x1122, LSB first
    assert crc16_rsdk(SAMPLE[:10]) == 0x42A2
    assert crc32_rsdk(SAMPLE[:-4]) == 0xBE97407B


def test_seed_sample_fed_whole() -> None:
    assert decode_all(SAMPLE) == [SAMPLE_FRAME]


def test_seed_sample_byte_by_byte() -> None:
    d = Decoder()
    for b in SAMPLE[:-1]:
        assert d.feed(bytes([b])) == []
    assert d.feed(SAMPLE[-1:]) == [SAMPLE_FRAME]


@pytest.mark.parametrize("cut", range(1, len(SAMPLE)))
def test_seed_sample_split_at_every_offset(cut: int) -> None:
    d = Decoder()
    assert d.feed(SAMPLE[:cut]) == []
    assert d.feed(SAMPLE[cut:]) == [SAMPLE_FRAME]
    assert d.pending == 0


@pytest.mark.parametrize(
    "garbage",
    [b"\x00", b"\xaa", b"\xaa\xaa\xaa", b"\x01\xaa\x1a\x00\x03", SAMPLE[:20], SAMPLE[1:], bytes(40)],
)
def test_seed_sample_after_garbage(garbage: bytes) -> None:
    out = decode_all(garbage + SAMPLE + garbage + SAMPLE)
    assert frames_of(out) == [SAMPLE_FRAME, SAMPLE_FRAME]
    assert sum(len(i.raw) for i in out if isinstance(i, BadFrame)) == 2 * len(garbage)


# --- CRCs ----------------------------------------------------------------------------------------


def test_crc_check_values() -> None:
    assert crc16_rsdk(b"123456789") == 0x2752
    assert crc16_fast(b"123456789") == 0x2752
    assert crc32_rsdk(b"123456789") == 0xE4D9DC14


@given(st.binary(max_size=64))
def test_fast_crc16_matches_shared_engine(data: bytes) -> None:
    assert crc16_fast(data) == crc16_rsdk(data)


@given(st.binary(min_size=1, max_size=64))
def test_crc32_residue_is_zero_after_own_value(data: bytes) -> None:
    """The decoder checks the CRC32 by hashing the whole frame: a valid one leaves a zero register."""
    framed = data + crc32_rsdk(data).to_bytes(4, "little")
    assert crc32_rsdk(framed) == 0
    assert zlib.crc32(framed, 0x3AA3 ^ 0xFFFFFFFF) == 0xFFFFFFFF


# --- header and frame checks ---------------------------------------------------------------------


def _with_header_crc(frame: bytearray) -> bytes:
    c = crc16_rsdk(frame[:10])
    frame[10:12] = c.to_bytes(2, "little")
    frame[-4:] = crc32_rsdk(frame[:-4]).to_bytes(4, "little")
    return bytes(frame)


def test_reasons() -> None:
    rules = FrameRules()
    bad_version = bytearray(SAMPLE)
    bad_version[2] |= 0x04
    assert rules.frame_length(_with_header_crc(bad_version)[:12]) == "version not 0"
    bad_hcrc = bytearray(SAMPLE)
    bad_hcrc[8] ^= 1
    assert rules.frame_length(bytes(bad_hcrc[:12])) == "header crc"
    bad_fcrc = bytearray(SAMPLE)
    bad_fcrc[15] ^= 1
    assert rules.parse(bytes(bad_fcrc)) == "frame crc"
    encrypted = encode(Frame(0x0E, 0, b"\x01", enc=0x20))
    assert rules.parse(encrypted) == "encrypted (unsupported)"


def test_bad_frames_reported_in_stream() -> None:
    bad = bytearray(SAMPLE)
    bad[15] ^= 1
    out = decode_all(bytes(bad) + SAMPLE)
    assert frames_of(out) == [SAMPLE_FRAME]
    assert isinstance(out[0], BadFrame) and out[0].reason == "frame crc"


def test_min_lengths_command_vs_legacy_reply() -> None:
    """A bare legacy return code is a 17-byte reply; a 17-byte command frame cannot exist."""
    reply = encode(Frame(None, None, b"\x00", seq=7, cmd_type=0, is_reply=True))
    assert len(reply) == 17
    assert decode_all(reply) == [Frame(None, None, b"\x00", 7, 0, True, 0)]
    cmd17 = bytearray(reply)
    cmd17[3] = 0x03  # same length, command frame
    cmd17 = bytearray(_with_header_crc(cmd17))
    assert FrameRules().frame_length(bytes(cmd17[:12])) == "length too short"
    header_only = bytearray(12)
    header_only[0:4] = b"\xaa\x0c\x00\x23"
    header_only[10:12] = crc16_rsdk(header_only[:10]).to_bytes(2, "little")
    assert FrameRules().frame_length(bytes(header_only)) == "length too short"


def test_command_frame_needs_cmdset() -> None:
    with pytest.raises(ValueError, match="CmdSet"):
        encode(Frame(None, None, b"\x00"))
    with pytest.raises(ValueError):
        encode(Frame(0x0E, None, b"\x00", is_reply=True))


@pytest.mark.parametrize(
    ("frame", "match"),
    [
        (Frame(0x0E, 0, b"", seq=0x10000), "seq"),
        (Frame(0x0E, 0, b"", seq=-1), "seq"),
        (Frame(0x0E, 0, b"", cmd_type=32), "cmd_type"),
        (Frame(0x100, 0, b""), "CmdSet"),
        (Frame(0x0E, 0, b"", enc=256), "enc"),
        (Frame(0x0E, 0, bytes(MAX_FRAME_LEN - 17)), "1023"),
    ],
)
def test_encode_rejects(frame: Frame, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        encode(frame)


def test_longest_frame_round_trips() -> None:
    f = Frame(0x0E, 0x0B, bytes(range(256)) * 3 + bytes(MAX_FRAME_LEN - 18 - 768), seq=1)
    raw = encode(f)
    assert len(raw) == MAX_FRAME_LEN
    assert decode_all(raw) == [f]


def test_pushes_pass() -> None:
    """0E 08 parameter pushes are 40-byte frames with the reply bit clear; 0E 10 carries TLV."""
    push = Frame(0x0E, 0x08, bytes(range(22)), seq=3, cmd_type=0)
    raw = encode(push)
    assert len(raw) == 40 and raw[3] == 0x00
    cal = Frame(0x0E, 0x10, bytes.fromhex("0006 01 32 00000000"), seq=4, cmd_type=0)
    assert decode_all(raw + encode(cal)) == [push, cal]


def test_reply_bit_and_properties() -> None:
    reply = Frame(0x0E, 0x00, b"\x00", seq=1, cmd_type=0, is_reply=True)
    raw = encode(reply)
    assert raw[3] == 0x20
    (got,) = decode_all(raw)
    assert got == reply and got.is_reply and not got.needs_reply
    assert got.data == b"\x0e\x00\x00" and got.key == (0x0E, 0x00)
    assert SAMPLE_FRAME.needs_reply
    legacy = Frame(None, None, b"\x00\x01\x02", is_reply=True, cmd_type=0)
    assert legacy.key is None and legacy.data == b"\x00\x01\x02"
    # the frame layer reads a legacy reply of >= 2 data bytes as if it were latest: data is kept
    (again,) = decode_all(encode(legacy))
    assert again.data == legacy.data and again.cmd_set == 0x00 and again.payload == b"\x02"


def test_decoded_frames_are_frozen_values() -> None:
    (f,) = decode_all(SAMPLE)
    assert type(f) is Frame and f == SAMPLE_FRAME and hash(f) == hash(SAMPLE_FRAME)
    with pytest.raises(AttributeError):
        f.seq = 1  # type: ignore[misc]


def test_stats() -> None:
    d = Decoder()
    d.feed(b"\x00\x01" + SAMPLE)
    assert (d.stats.frames, d.stats.bad_frames, d.stats.dropped_bytes) == (1, 1, 2)


def test_codec_modules_import_only_stdlib_and_wire() -> None:
    root = pathlib.Path(__file__).resolve().parents[1] / "adapters" / "rsdk"
    allowed_local = {"adapters.wire", "adapters.errors", "adapters.rsdk.protocol"}
    for name in ("protocol.py", "commands.py", "can.py", "candump.py"):
        tree = ast.parse((root / name).read_text())
        for node in ast.walk(tree):
            mods = []
            if isinstance(node, ast.Import):
                mods = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                mods = [node.module]
            for m in mods:
                top = m.split(".")[0]
                ok = top in sys.stdlib_module_names or any(m.startswith(p) for p in allowed_local)
                assert ok, f"{name} imports {m}"


# --- properties ----------------------------------------------------------------------------------

frame_st = st.builds(
    Frame,
    cmd_set=st.integers(0, 255),
    cmd_id=st.integers(0, 255),
    payload=st.binary(max_size=80),
    seq=st.integers(0, 0xFFFF),
    cmd_type=st.integers(0, 31),
    is_reply=st.booleans(),
    enc=st.integers(0, 0x1F),
)


@given(frame_st)
def test_round_trip(frame: Frame) -> None:
    assert decode_all(encode(frame)) == [frame]


@given(st.binary(max_size=600), st.integers(1, 64))
def test_random_bytes_never_raise_nor_stall(data: bytes, chunk: int) -> None:
    out = decode_all(data, chunk)
    # every input byte is accounted for: in a frame or in a BadFrame
    accounted = sum(len(i.raw) for i in out if isinstance(i, BadFrame))
    accounted += sum(len(encode(f)) for f in frames_of(out))
    assert accounted == len(data)


@given(st.lists(st.tuples(st.binary(max_size=40), frame_st), max_size=6), st.integers(1, 40))
def test_valid_frames_after_garbage_are_found(parts: list[tuple[bytes, Frame]], chunk: int) -> None:
    stream = b"".join(garbage + encode(f) for garbage, f in parts)
    assert frames_of(decode_all(stream, chunk)) == [f for _, f in parts]


@given(frame_st, frame_st, st.data())
def test_frame_cut_at_any_offset_then_valid_frame(a: Frame, b: Frame, data: st.DataObject) -> None:
    raw_a = encode(a)
    cut = data.draw(st.integers(1, len(raw_a) - 1))
    # when a's missing tail happens to equal b's first bytes, a really is complete on the wire
    assume(not encode(b).startswith(raw_a[cut:]))
    out = decode_all(raw_a[:cut] + encode(b))
    assert frames_of(out) == [b]
    assert sum(len(i.raw) for i in out if isinstance(i, BadFrame)) == cut


@pytest.mark.parametrize("cut", range(1, len(SAMPLE)))
def test_truncated_sample_flushes_to_bad_frames(cut: int) -> None:
    out = decode_all(SAMPLE[:cut])
    assert out and all(isinstance(i, BadFrame) for i in out)
    assert b"".join(i.raw for i in out) == SAMPLE[:cut]
