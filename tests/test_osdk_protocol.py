"""OSDK framing (header bytes, CRCs, validation, stream resync) and the session rules."""

from __future__ import annotations

import ast
import struct
import sys
from pathlib import Path

import crc
import pytest
from hypothesis import given
from hypothesis import strategies as st

from adapters.errors import FrameError, SessionsExhausted
from adapters.osdk.protocol import (
    ENCRYPTED_REASON,
    MAX_FRAME_LEN,
    BadFrame,
    Decoder,
    DuplicateFilter,
    Frame,
    SessionMode,
    SessionTable,
    decode_frame,
    encode_ack,
    encode_command,
    encode_frame,
)

# Independent CRC oracles: the seed's pycrc models (init written unreflected), not our engines.
C16 = crc.Calculator(
    crc.Configuration(
        width=16,
        polynomial=0x8005,
        init_value=0xC55C,
        final_xor_value=0,
        reverse_input=True,
        reverse_output=True,
    )
)
C32 = crc.Calculator(
    crc.Configuration(
        width=32,
        polynomial=0x04C11DB7,
        init_value=0xC55C0000,
        final_xor_value=0,
        reverse_input=True,
        reverse_output=True,
    )
)

# Seed 000 section 3.3: the R SDK sample frame. The OSDK header is the same, so it is a valid OSDK
# command frame (CmdType 0x03 = session 3), CmdSet 0x0E, CmdID 0x00, seq 0x1122.
SEED_SAMPLE = bytes.fromhex("AA1A000300000000 2211 A242 0E00 2000300040000114 7B4097BE".replace(" ", ""))
HAND_BUILT = bytes.fromhex("aa 13 00 05 00 00 00 00 34 12 e0 73 03 12 01 87 f3 3a c3".replace(" ", ""))
HEADER_ONLY = bytes.fromhex("aa 0c 00 23 00 00 00 00 01 00 bc dc".replace(" ", ""))


def _header(length_word: int, b3: int, b4: int, reserved: bytes, seq: int) -> bytes:
    h = bytes([0xAA]) + struct.pack("<H", length_word) + bytes([b3, b4]) + reserved + struct.pack("<H", seq)
    return h + C16.checksum(h).to_bytes(2, "little")


def _frame(
    length_word: int, b3: int, b4: int, data: bytes, reserved: bytes = b"\0\0\0", seq: int = 1
) -> bytes:
    body = _header(length_word, b3, b4, reserved, seq) + data
    return body + C32.checksum(body).to_bytes(4, "little") if data else body


def _decode_all(chunks: list[bytes]) -> list[Frame | BadFrame]:
    dec = Decoder()
    out: list[Frame | BadFrame] = []
    for c in chunks:
        out += dec.feed(c)
    out += dec.flush()
    assert dec.pending == 0
    return out


def _frames(items: list[Frame | BadFrame]) -> list[Frame]:
    return [i for i in items if isinstance(i, Frame)]


# ---------------------------------------------------------------------------------------------- header


def test_crc_oracles_match_the_notes_check_values() -> None:
    assert C16.checksum(b"123456789") == 0x2752
    assert C32.checksum(b"123456789") == 0xE4D9DC14


def test_hand_built_command_frame_byte_by_byte() -> None:
    frame = encode_command(0x03, 0x12, b"\x01", session=5, seq=0x1234)
    assert frame == HAND_BUILT
    assert frame[0] == 0xAA  # SOF
    assert struct.unpack_from("<H", frame, 1)[0] == 19 == len(frame)  # length | version 0 << 10
    assert frame[3] == 5  # session 5, ack bit 0, reserved 0
    assert frame[4] == 0  # padding 0, enc 0
    assert frame[5:8] == b"\0\0\0"
    assert frame[8:10] == b"\x34\x12"  # seq LE
    assert frame[10:12] == C16.checksum(frame[:10]).to_bytes(2, "little")
    assert frame[12:15] == b"\x03\x12\x01"  # CmdSet, CmdID, payload
    assert frame[15:] == C32.checksum(frame[:15]).to_bytes(4, "little")
    f = decode_frame(frame)
    assert f == Frame(session=5, is_ack=False, seq=0x1234, data=b"\x03\x12\x01")
    assert (f.cmd_set, f.cmd_id, f.payload) == (0x03, 0x12, b"\x01")
    assert f.encode() == frame


def test_header_only_frame_is_exactly_12_bytes_without_crc32() -> None:
    frame = encode_ack(3, 1, b"")
    assert frame == HEADER_ONLY
    assert len(frame) == 12
    assert struct.unpack_from("<H", frame, 1)[0] == 12
    assert frame[3] == 0x23  # session 3 | ack << 5
    assert frame[10:12] == C16.checksum(frame[:10]).to_bytes(2, "little")
    assert decode_frame(frame) == Frame(session=3, is_ack=True, seq=1, data=b"")


def test_ack_frame_carries_only_the_ack_value() -> None:
    frame = encode_ack(7, 0xBEEF, b"\x02\x00")
    f = decode_frame(frame)
    assert f.is_ack and f.session == 7 and f.seq == 0xBEEF
    assert f.data == f.payload == b"\x02\x00"
    assert f.cmd_set is None and f.cmd_id is None
    assert frame[3] == 0x27
    assert len(frame) == 12 + 2 + 4


def test_seed_sample_frame_decodes_as_osdk_command() -> None:
    f = decode_frame(SEED_SAMPLE)
    assert (f.session, f.is_ack, f.seq, f.cmd_set, f.cmd_id) == (3, False, 0x1122, 0x0E, 0x00)
    assert f.payload == bytes.fromhex("2000300040000114")
    assert encode_command(0x0E, 0x00, f.payload, 3, 0x1122) == SEED_SAMPLE


def test_crc32_over_data_frame_with_empty_data_is_accepted() -> None:
    # Length 16 = header + CRC32 with no data: OSDK's receiver accepts it; only ACKs can be empty.
    raw = _frame(16, 0x22, 0, b"")
    raw = raw + C32.checksum(raw).to_bytes(4, "little")
    assert decode_frame(raw) == Frame(2, True, 1, b"")


@pytest.mark.parametrize(
    ("raw", "reason"),
    [
        (_frame(19 | 1 << 10, 0x02, 0, b"\x03\x10\x00"), "version 1"),
        (_frame(19, 0x42, 0, b"\x03\x10\x00"), "reserved bits set"),
        (_frame(19, 0x02, 0, b"\x03\x10\x00", reserved=b"\0\x01\0"), "reserved bits set"),
        (_frame(19, 0x02, 0x20, b"\x03\x10\x00"), ENCRYPTED_REASON),
        (_frame(13, 0x02, 0, b""), "bad length 13"),
        (_frame(11, 0x02, 0, b""), "bad length 11"),
        (_frame(12, 0x02, 0, b""), "command frame without CmdSet/CmdID"),
        (HAND_BUILT[:10] + b"\0\0" + HAND_BUILT[12:], "header crc"),
        (HAND_BUILT[:-1] + bytes([HAND_BUILT[-1] ^ 1]), "frame crc"),
        (HAND_BUILT[:14] + b"\x00" + HAND_BUILT[15:], "frame crc"),
    ],
)
def test_receive_validation(raw: bytes, reason: str) -> None:
    with pytest.raises(FrameError, match=reason):
        decode_frame(raw)
    items = _decode_all([raw])
    assert not _frames(items)
    first = items[0]
    assert isinstance(first, BadFrame)
    assert first == BadFrame(reason, raw[: len(first.raw)])


def test_encrypted_frame_is_a_clear_bad_frame_and_the_next_frame_survives() -> None:
    enc = _frame(19, 0x02, 0x21, b"\x03\x10\x00")  # enc 1, padding 1
    items = _decode_all([enc + HAND_BUILT])
    assert items[0] == BadFrame(ENCRYPTED_REASON, enc)
    assert _frames(items) == [decode_frame(HAND_BUILT)]


def test_encode_limits() -> None:
    assert len(encode_frame(b"x" * (MAX_FRAME_LEN - 16), session=0, seq=0)) == MAX_FRAME_LEN
    with pytest.raises(FrameError, match="at most 1023"):
        encode_frame(b"x" * (MAX_FRAME_LEN - 15), session=0, seq=0)
    with pytest.raises(FrameError, match="session 32"):
        encode_command(1, 3, b"", 32, 0)
    with pytest.raises(FrameError, match="seq"):
        encode_command(1, 3, b"", 0, 0x10000)
    with pytest.raises(FrameError, match="must be bytes"):
        encode_command(0x100, 3, b"", 0, 0)


def test_decode_frame_rejects_partial_and_extra_bytes() -> None:
    with pytest.raises(FrameError, match="announces 19 bytes, got 20"):
        decode_frame(HAND_BUILT + b"\0")
    with pytest.raises(FrameError, match="too short"):
        decode_frame(HAND_BUILT[:5])


# ---------------------------------------------------------------------------------------------- stream

STREAM_FRAMES = [
    HAND_BUILT,
    HEADER_ONLY,
    SEED_SAMPLE,
    encode_ack(9, 0x0102, b"\x00\x00"),
    encode_command(0x02, 0x00, b"\x02\x00" + bytes(16), 0, 77),
    encode_command(0x03, 0x11, bytes(90), 4, 0xFFFF),
]
STREAM = b"".join(STREAM_FRAMES)
EXPECTED = [decode_frame(f) for f in STREAM_FRAMES]


def test_stream_fed_whole() -> None:
    assert _decode_all([STREAM]) == EXPECTED


def test_stream_fed_byte_by_byte() -> None:
    assert _decode_all([bytes([b]) for b in STREAM]) == EXPECTED


def test_stream_split_at_every_offset() -> None:
    for i in range(len(STREAM) + 1):
        assert _decode_all([STREAM[:i], STREAM[i:]]) == EXPECTED, i


def test_stream_after_garbage_with_false_sofs() -> None:
    garbage = b"\x00\xaa\xaa\x13\x00\xff" + HAND_BUILT[:11] + b"\xaa"  # includes a truncated real header
    for g in (garbage, b"\xaa" * 30, HAND_BUILT[:-1]):
        items = _decode_all([g + STREAM])
        assert _frames(items) == EXPECTED
        assert isinstance(items[0], BadFrame)
        # every byte is accounted for, exactly once
        dropped = sum(len(i.raw) for i in items if isinstance(i, BadFrame))
        assert dropped == len(g)


def test_truncated_frame_at_end_is_reported_by_flush() -> None:
    dec = Decoder()
    assert dec.feed(HAND_BUILT + HAND_BUILT[:15]) == [decode_frame(HAND_BUILT)]
    assert dec.pending == 15
    out = dec.flush()
    assert out and all(isinstance(i, BadFrame) for i in out)
    assert b"".join(i.raw for i in out if isinstance(i, BadFrame)) == HAND_BUILT[:15]


@given(st.binary(max_size=400), st.lists(st.integers(1, 64), max_size=20))
def test_random_bytes_never_raise_and_never_stall(data: bytes, cuts: list[int]) -> None:
    dec = Decoder()
    out: list[Frame | BadFrame] = []
    pos = 0
    for c in cuts:
        out += dec.feed(data[pos : pos + c])
        pos += c
    out += dec.feed(data[pos:])
    out += dec.flush()
    assert dec.pending == 0
    consumed = sum(len(i.raw) if isinstance(i, BadFrame) else len(i.encode()) for i in out)
    assert consumed == len(data)


@given(st.binary(max_size=200), st.binary(max_size=200), st.integers(0, len(STREAM)))
def test_valid_frames_after_garbage_are_found(before: bytes, after: bytes, cut: int) -> None:
    data = before + STREAM + after
    cut = min(cut, len(data))
    found = _frames(_decode_all([data[:cut], data[cut:]]))
    it = iter(found)
    assert all(any(f == g for g in it) for f in EXPECTED)  # EXPECTED is a subsequence of what was found


@given(
    st.integers(0, 31),
    st.booleans(),
    st.integers(0, 0xFFFF),
    st.binary(min_size=2, max_size=MAX_FRAME_LEN - 16),
)
def test_encode_decode_round_trip(session: int, is_ack: bool, seq: int, data: bytes) -> None:
    raw = encode_frame(data, session=session, seq=seq, is_ack=is_ack)
    assert decode_frame(raw) == Frame(session, is_ack, seq, data)
    assert _decode_all([raw]) == [Frame(session, is_ack, seq, data)]


# ---------------------------------------------------------------------------------------------- sessions


def test_sessions_allocated_2_to_31_then_exhausted_then_freed_by_ack() -> None:
    t = SessionTable()
    sent = [t.send(0x03, 0x12, b"\x00", now=0.0) for _ in range(30)]
    assert sorted(s.session for s in sent) == list(range(2, 32))
    assert [s.seq for s in sent] == list(range(30))
    with pytest.raises(SessionsExhausted):
        t.send(0x03, 0x12, b"\x00", now=0.0)
    freed = sent[10]
    assert t.on_ack(decode_frame(encode_ack(freed.session, freed.seq, b"\x00"))) is not None
    again = t.send(0x03, 0x12, b"\x00", now=0.0)
    assert again.session == freed.session
    assert again.seq == 30  # one global seq; the failed send did not consume one


def test_round_robin_does_not_reuse_a_just_freed_session() -> None:
    t = SessionTable()
    a = t.send(1, 0, b"\x01", now=0.0)
    t.on_ack(decode_frame(encode_ack(a.session, a.seq, b"\x02\x00")))
    b = t.send(1, 0, b"\x01", now=0.0)
    assert (a.session, b.session) == (2, 3)


def test_no_ack_and_tolerant_sessions() -> None:
    t = SessionTable(first_seq=0xFFFF)
    s0 = t.send(0x01, 0x03, bytes(17), now=0.0, mode=SessionMode.NO_ACK)
    s1 = t.send(0x01, 0x00, b"\x01", now=0.0, mode=SessionMode.ACK_TOLERANT, retries=5)
    assert (s0.session, s0.seq) == (0, 0xFFFF)
    assert (s1.session, s1.seq) == (1, 0)  # seq wraps
    assert decode_frame(s0.frame).session == 0
    assert [p.seq for p in t.pending] == [0]
    res = t.poll(0.5)
    assert res.resend == ()  # session 1 is never resent
    assert [p.seq for p in res.expired] == [0]
    assert t.pending == ()


def test_retransmits_the_same_bytes_then_expires() -> None:
    t = SessionTable(first_seq=100)
    sent = t.send(0x03, 0x10, bytes(51), now=10.0, timeout=0.5, retries=2, tag="init")
    assert t.next_deadline() == 10.5
    assert t.poll(10.49).resend == ()
    first = t.poll(10.5)
    assert first.resend == (sent.frame,) and first.expired == ()
    assert t.next_deadline() == 11.0
    second = t.poll(11.0)
    assert second.resend == (sent.frame,)
    assert decode_frame(second.resend[0]).seq == 100  # same session, same seq
    third = t.poll(11.5)
    assert third.resend == ()
    assert [(p.session, p.seq, p.tag, p.cmd_set, p.cmd_id) for p in third.expired] == [
        (2, 100, "init", 3, 0x10)
    ]
    assert t.poll(100.0) == type(third)()
    assert t.next_deadline() is None


def test_ack_matched_by_session_and_seq_only() -> None:
    t = SessionTable()
    a = t.send(0x03, 0x12, b"\x00", now=0.0)
    b = t.send(0x03, 0x13, b"\x00", now=0.0)
    assert t.on_ack(decode_frame(encode_ack(a.session, b.seq, b"\x00"))) is None  # wrong pairing
    assert t.on_ack(decode_frame(encode_command(0x03, 0x12, b"\x00", a.session, a.seq))) is None  # not an ACK
    got = t.on_ack(decode_frame(encode_ack(b.session, b.seq, b"\x00")))
    assert got is not None and (got.cmd_id, got.seq) == (0x13, b.seq)
    assert t.on_ack(decode_frame(encode_ack(b.session, b.seq, b"\x00"))) is None  # late duplicate ACK
    assert [p.seq for p in t.clear()] == [a.seq]
    assert t.pending == ()


def test_duplicate_filter_resends_stored_ack_instead_of_acting_twice() -> None:
    rx = DuplicateFilter()
    cmd = decode_frame(encode_command(0x03, 0x12, b"\x00", 4, 9))
    assert not rx.check(cmd).duplicate
    # the retransmission arrives before we answered: drop it, nothing to resend yet
    assert rx.check(cmd).duplicate and rx.check(cmd).resend is None
    ack = rx.ack(cmd, b"\x00")
    assert decode_frame(ack) == Frame(4, True, 9, b"\x00")
    verdict = rx.check(cmd)
    assert verdict.duplicate and verdict.resend == ack
    # a new seq on the same session, or the same seq on another session, is new
    assert not rx.check(decode_frame(encode_command(0x03, 0x12, b"\x00", 4, 10))).duplicate
    assert not rx.check(decode_frame(encode_command(0x03, 0x12, b"\x00", 5, 9))).duplicate
    # session 0 wants no ACK and is never suppressed
    s0 = decode_frame(encode_command(0x01, 0x03, bytes(17), 0, 9))
    assert not rx.check(s0).duplicate and not rx.check(s0).duplicate
    rx.reset()
    assert not rx.check(cmd).duplicate


def test_lost_ack_end_to_end_command_runs_once() -> None:
    """Sender and receiver over a link that loses the first ACK: one execution, one match."""
    tx, rx = SessionTable(), DuplicateFilter()
    executed: list[int] = []

    def receive(raw: bytes) -> bytes | None:
        (frame,) = _frames(_decode_all([raw]))
        verdict = rx.check(frame)
        if verdict.duplicate:
            return verdict.resend
        executed.append(frame.seq)
        return rx.ack(frame, b"\x00")

    sent = tx.send(0x03, 0x12, b"\x00", now=0.0)
    assert receive(sent.frame) is not None  # ACK lost on the way back
    (again,) = tx.poll(0.5).resend
    ack = receive(again)
    assert ack is not None
    (ack_frame,) = _frames(_decode_all([ack]))
    assert tx.on_ack(ack_frame) is not None
    assert executed == [sent.seq]
    assert tx.pending == ()


# ---------------------------------------------------------------------------------------------- house rules


@pytest.mark.parametrize("module", ["protocol.py", "commands.py"])
def test_codec_modules_import_only_stdlib_and_adapters(module: str) -> None:
    tree = ast.parse((Path(__file__).parents[1] / "adapters" / "osdk" / module).read_text())
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module]
        for name in names:
            top = name.split(".")[0]
            allowed = ("adapters.wire", "adapters.osdk", "adapters.errors")
            assert top in sys.stdlib_module_names or name.startswith(allowed), name
