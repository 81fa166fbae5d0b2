"""R SDK over CAN: segmentation, reassembly (foreign ids, lost CAN frames, the restart rule) and
candump parsing."""

from __future__ import annotations

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.rsdk import describe
from adapters.rsdk.can import GIMBAL_TX_ID, HOST_TX_ID, Reassembler, segment
from adapters.rsdk.candump import parse_line, parse_lines
from adapters.rsdk.protocol import BadFrame, Frame, FrameRules, encode
from tests.rsdk_can_reference import ReferenceReassembler

RULES = FrameRules()
SAMPLE = bytes.fromhex("AA1A0003000000002211A2420E0020003000400001147B4097BE")


def frames_of(items: list) -> list[Frame]:
    return [i for i in items if isinstance(i, Frame)]


def feed_all(r: Reassembler, can_frames: list[tuple[int, bytes]], flush: bool = True) -> list:
    out: list = []
    for arb_id, data in can_frames:
        out += r.feed(arb_id, data)
    if flush:
        out += r.flush()
    return out


def mk(n_payload: int, seq: int, fill: int = 0x11, reply: bool = False) -> Frame:
    return Frame(0x0E, 0x08, bytes([fill]) * n_payload, seq=seq, cmd_type=0, is_reply=reply)


# a spread of lengths: 17 (legacy reply), 18, 24, 25, 26 (seed), 32, 40 (push), 60
FRAMES = [
    Frame(None, None, b"\x00", seq=1, cmd_type=0, is_reply=True),
    mk(0, 2),
    mk(6, 3),
    mk(7, 4),
    Frame(0x0E, 0x00, bytes.fromhex("2000300040000114"), seq=0x1122),
    mk(14, 5),
    mk(22, 6),
    mk(42, 7),
]


# --- segmentation --------------------------------------------------------------------------------


def test_segment_seed_sample() -> None:
    parts = segment(SAMPLE)
    assert [i for i, _ in parts] == [HOST_TX_ID] * 4
    assert [len(d) for _, d in parts] == [8, 8, 8, 2]
    assert b"".join(d for _, d in parts) == SAMPLE
    assert all(i == GIMBAL_TX_ID for i, _ in segment(SAMPLE, GIMBAL_TX_ID))


@pytest.mark.parametrize("frame", FRAMES, ids=lambda f: f"len{len(encode(f))}")
def test_round_trip_both_directions(frame: Frame) -> None:
    raw = encode(frame)
    assert frames_of(feed_all(Reassembler(), segment(raw, GIMBAL_TX_ID))) == [frame]  # host side
    assert frames_of(feed_all(Reassembler(HOST_TX_ID), segment(raw))) == [frame]  # gimbal simulator side


def test_frame_reported_on_its_last_can_frame() -> None:
    r = Reassembler()
    parts = segment(SAMPLE, GIMBAL_TX_ID)
    for arb_id, data in parts[:-1]:
        assert r.feed(arb_id, data) == []
    (f,) = r.feed(*parts[-1])
    assert isinstance(f, Frame) and f.seq == 0x1122


def test_foreign_ids_ignored_and_interleaved() -> None:
    host = [segment(encode(f), GIMBAL_TX_ID) for f in FRAMES]
    noise = [(0x100, b"\xaa\x00\x01"), (HOST_TX_ID, SAMPLE[:8]), (0x7FF, b""), (HOST_TX_ID, b"\xaa" * 8)]
    stream: list[tuple[int, bytes]] = []
    for k, parts in enumerate(host):
        for j, part in enumerate(parts):
            stream.append(part)
            stream.append(noise[(k + j) % len(noise)])
    out = feed_all(Reassembler(), stream)
    assert out == FRAMES  # no BadFrame at all: other ids never reach the decoder


def test_two_directions_on_one_bus() -> None:
    cmd = Frame(0x0E, 0x02, b"\x01", seq=9)
    rep = Frame(0x0E, 0x02, bytes(8), seq=9, cmd_type=0, is_reply=True)
    a, b = segment(encode(cmd), HOST_TX_ID), segment(encode(rep), GIMBAL_TX_ID)
    bus = [x for pair in zip(a, b, strict=False) for x in pair] + b[len(a) :]
    host, gimbal = Reassembler(GIMBAL_TX_ID), Reassembler(HOST_TX_ID)
    assert frames_of(feed_all(host, bus)) == [rep]
    assert frames_of(feed_all(gimbal, bus)) == [cmd]


def test_oversized_can_frame_reported() -> None:
    (bad,) = Reassembler().feed(GIMBAL_TX_ID, bytes(9))
    assert isinstance(bad, BadFrame) and "8 bytes" in bad.reason


# --- lost CAN frames and the restart rule --------------------------------------------------------


@pytest.mark.parametrize("a", FRAMES, ids=lambda f: f"A{len(encode(f))}")
@pytest.mark.parametrize("b", FRAMES[::3], ids=lambda f: f"B{len(encode(f))}")
def test_single_lost_can_frame_does_not_delay_the_next_frame(a: Frame, b: Frame) -> None:
    parts_a = segment(encode(a), GIMBAL_TX_ID)
    parts_b = segment(encode(b), GIMBAL_TX_ID)
    for lost in range(len(parts_a)):
        r = Reassembler()
        out: list = []
        for part in parts_a[:lost] + parts_a[lost + 1 :] + parts_b[:-1]:
            out += r.feed(*part)
        assert frames_of(out) == []
        last = r.feed(*parts_b[-1])
        assert frames_of(last) == [b], f"lost CAN frame {lost}"
        assert r.decoder.pending == 0
        assert r.flush() == []
        bad = [i for i in out + last if isinstance(i, BadFrame)]
        assert sum(len(i.raw) for i in bad) == len(encode(a)) - len(parts_a[lost][1])


def test_restart_reports_the_broken_frame_when_the_next_one_starts() -> None:
    """The last CAN frame of A (2 bytes) is lost: B's first CAN frame (8 bytes, 0xAA) cannot finish A."""
    parts_a = segment(SAMPLE, GIMBAL_TX_ID)
    b = encode(mk(6, 3))
    r = Reassembler()
    for part in parts_a[:-1]:
        assert r.feed(*part) == []
    out = r.feed(GIMBAL_TX_ID, b[:8])
    assert out and all(isinstance(i, BadFrame) for i in out)
    assert out[0].reason == "incomplete frame"
    assert b"".join(i.raw for i in out) == SAMPLE[:24]
    assert r.decoder.pending == 8  # B is the candidate now


def test_restart_finds_a_frame_that_began_inside_the_broken_one() -> None:
    """A lost 12 bytes; B's first CAN frame was taken as A's continuation; B's second CAN frame
    happens to start with 0xAA and cannot continue A (4 bytes missing): the rescan must find B in
    the held bytes rather than drop them."""
    a = encode(mk(42, 7))  # 60 bytes: 7 CAN frames of 8, then 4
    b_frame = Frame(0x0E, 0x08, b"\x22" * 14, seq=0x12AA, cmd_type=0)  # seq low byte 0xAA
    b = encode(b_frame)
    assert b[8] == 0xAA and len(b) == 32
    parts_a = segment(a, GIMBAL_TX_ID)
    kept = parts_a[:5] + parts_a[6:7]  # CAN frame 5 and the last one lost: 12 bytes missing
    r = Reassembler()
    out = feed_all(r, [*kept, *segment(b, GIMBAL_TX_ID)[:2]], flush=False)
    assert frames_of(out) == [] and out[0].reason == "incomplete frame" and out[0].raw[:1] == b"\xaa"
    assert r.decoder.pending == 16  # B's first two CAN frames are the candidate now
    parts_b = segment(b, GIMBAL_TX_ID)
    assert r.feed(*parts_b[2]) == []
    assert r.feed(*parts_b[3]) == [b_frame]


def test_short_can_frame_inside_a_candidate_ends_it_at_the_next_start() -> None:
    """A (64 bytes) lost 5 CAN frames after its header, so it swallows all of B (19 bytes, ending in
    a 3-byte CAN frame). When C starts, rule 2 fails A at once and B is found, not only after A's
    length is met."""
    a = encode(mk(46, 1))
    assert len(a) == 64
    b_frame, c_frame = mk(1, 2, fill=0x33), mk(1, 3, fill=0x44)
    parts_a = segment(a, GIMBAL_TX_ID)
    r = Reassembler()
    feed_all(r, [*parts_a[:2], parts_a[7], *segment(encode(b_frame), GIMBAL_TX_ID)], flush=False)
    c_parts = segment(encode(c_frame), GIMBAL_TX_ID)
    assert frames_of(r.feed(*c_parts[0])) == [b_frame]
    assert frames_of(feed_all(r, c_parts[1:])) == [c_frame]


@pytest.mark.parametrize("where", [16, 24, 32, 40])
def test_aa_at_a_can_boundary_inside_a_frame_is_data(where: int) -> None:
    payload = bytearray(b"\x01" * 30)
    payload[where - 14] = 0xAA  # data starts at frame byte 14
    f = Frame(0x0E, 0x0B, bytes(payload), seq=0x00AA)  # seq low byte: 0xAA at byte 8 as well
    raw = encode(f)
    assert raw[8] == raw[where] == 0xAA
    assert feed_all(Reassembler(), segment(raw, GIMBAL_TX_ID)) == [f]


def test_over_long_can_frame_is_rejected_even_if_it_would_finish_the_frame() -> None:
    """9 bytes are never a CAN payload: the frame they would complete stays incomplete."""
    raw = encode(mk(7, 1))
    assert len(raw) == 25
    r = Reassembler()
    assert feed_all(r, [(GIMBAL_TX_ID, raw[:8]), (GIMBAL_TX_ID, raw[8:16])], flush=False) == []
    (bad,) = r.feed(GIMBAL_TX_ID, raw[16:])
    assert isinstance(bad, BadFrame) and "8 bytes" in bad.reason
    assert r.decoder.pending == 16 and r.decoder.stats.frames == 0


# 0xAA is frequent on purpose: it puts false SOFs at CAN frame starts, where the restart rule acts
_byte = st.sampled_from([0x00, 0xAA, 0x55, 0x0E])
frame_st = st.builds(
    Frame,
    cmd_set=_byte,
    cmd_id=_byte,
    payload=st.lists(_byte, max_size=60).map(bytes),
    seq=st.sampled_from([0, 0xAA, 0xAAAA, 0x1234, 0xAA00]),
    cmd_type=st.integers(0, 31),
    is_reply=st.booleans(),
)


@given(st.lists(st.tuples(frame_st, st.sets(st.integers(0, 9), max_size=3)), min_size=1, max_size=6))
def test_lost_can_frames_never_hide_intact_frames(plan: list[tuple[Frame, set[int]]]) -> None:
    """Every frame whose CAN frames all arrived is reported, in order, whatever was lost around it."""
    stream: list[tuple[int, bytes]] = []
    intact = []
    for frame, lost in plan:
        parts = segment(encode(frame), GIMBAL_TX_ID)
        kept = [p for k, p in enumerate(parts) if k not in lost]
        stream += kept
        if len(kept) == len(parts):
            intact.append(frame)
    found = frames_of(feed_all(Reassembler(), stream))
    sent = [f for f, _ in plan]
    # CAN frames of equal frames can splice into one more valid copy; nothing else may appear
    assert all(f in sent for f in found)
    rest = iter(found)
    assert all(any(f == g for g in rest) for f in intact), "an intact frame was not found, in order"


@given(st.lists(st.binary(max_size=8), max_size=40))
def test_random_can_frames_never_raise_nor_stall(payloads: list[bytes]) -> None:
    r = Reassembler()
    out = feed_all(r, [(GIMBAL_TX_ID, p) for p in payloads])
    assert r.decoder.pending == 0
    accounted = sum(len(i.raw) for i in out if isinstance(i, BadFrame)) + sum(
        len(encode(f)) for f in frames_of(out)
    )
    assert accounted == sum(len(p) for p in payloads)


# --- the fast path changes nothing: equivalence with the reassembler before it -------------------


@st.composite
def _can_frames_of_one_frame(draw: st.DrawFn) -> list[tuple[int, bytes | bytearray]]:
    """One R SDK frame on the bus, mostly as sent, often damaged the ways a bus and a host damage it."""
    kind = draw(st.sampled_from(["frame", "frame", "frame", "legacy", "encrypted"]))
    if kind == "legacy":
        frame = Frame(
            None, None, bytes([draw(_byte)]), seq=draw(st.integers(0, 0xFFFF)), cmd_type=0, is_reply=True
        )
    else:
        frame = draw(frame_st)
        if kind == "encrypted":
            frame = Frame(
                frame.cmd_set, frame.cmd_id, frame.payload, frame.seq, frame.cmd_type, frame.is_reply, 0x20
            )
    raw = bytearray(encode(frame))
    if draw(st.integers(0, 3)) == 0:  # a flipped bit: bad version/length/header CRC/frame CRC
        raw[draw(st.integers(0, len(raw) - 1))] ^= 1 << draw(st.integers(0, 7))
    if draw(st.integers(0, 4)) == 0:  # the frame does not start at byte 0 of a CAN frame
        raw[:0] = bytes(draw(st.lists(_byte, min_size=1, max_size=7)))
    if draw(st.integers(0, 5)) == 0:  # the sender stopped early
        del raw[draw(st.integers(1, len(raw) - 1)) :]
    if draw(st.integers(0, 3)) == 0:  # irregular cuts (a host that does not follow the rule, or > 8 bytes)
        sizes = draw(st.lists(st.sampled_from([8, 8, 8, 1, 3, 7, 9]), min_size=1, max_size=12))
        parts, i, k = [], 0, 0
        while i < len(raw):
            parts.append(bytes(raw[i : i + sizes[k % len(sizes)]]))
            i, k = i + sizes[k % len(sizes)], k + 1
    else:
        parts = [d for _, d in segment(bytes(raw), GIMBAL_TX_ID)]
    if len(parts) > 1 and draw(st.integers(0, 3)) == 0:  # a CAN frame takes bytes of the next (> 8 bytes)
        k = draw(st.sampled_from([len(parts) - 2, draw(st.integers(0, len(parts) - 2))]))
        take = draw(st.sampled_from([1, len(parts[k + 1])]))
        parts[k : k + 2] = [p for p in (parts[k] + parts[k + 1][:take], parts[k + 1][take:]) if p]
    if draw(st.integers(0, 4)) == 0:  # the rest comes later, if at all (a flush or a reset may come first)
        parts = parts[: draw(st.integers(1, len(parts)))]
    out: list[tuple[int, bytes | bytearray]] = []
    n_parts = len(parts)
    lost = draw(st.sets(st.integers(0, n_parts - 1), max_size=2)) if draw(st.booleans()) else set()
    dup = draw(st.sets(st.integers(0, n_parts - 1), max_size=2)) if draw(st.integers(0, 3)) == 0 else set()
    short = draw(st.sets(st.integers(0, n_parts - 1), max_size=1)) if draw(st.integers(0, 5)) == 0 else set()
    arb = GIMBAL_TX_ID if draw(st.integers(0, 9)) else HOST_TX_ID
    for k, part in enumerate(parts):
        if k in lost:
            continue
        if k in short:
            part = part[: draw(st.integers(0, max(0, len(part) - 1)))]
        if draw(st.integers(0, 9)) == 0:  # another id in between
            out.append((draw(st.sampled_from([HOST_TX_ID, 0x100])), bytes(draw(st.lists(_byte, max_size=8)))))
        data: bytes | bytearray = bytearray(part) if draw(st.integers(0, 7)) == 0 else part
        out.extend([(arb, data)] * (2 if k in dup else 1))
    return out


_bus_op = st.one_of(
    _can_frames_of_one_frame(),
    _can_frames_of_one_frame(),
    _can_frames_of_one_frame(),
    st.tuples(  # one stray CAN frame (0xAA-heavy), possibly over-long or on another id
        st.sampled_from([GIMBAL_TX_ID, GIMBAL_TX_ID, GIMBAL_TX_ID, HOST_TX_ID]),
        st.one_of(st.lists(_byte, max_size=9).map(bytes), st.binary(max_size=9)),
    ).map(lambda p: [p]),
    st.just("flush"),
    st.just("reset"),
)


@settings(max_examples=500)
@given(st.lists(_bus_op, max_size=12))
def test_same_results_as_the_reference_reassembler(ops: list) -> None:
    """Every item, in order, and every counter and held byte count after every call, are those of the
    verbatim pre-fast-path class (tests/rsdk_can_reference.py), whatever the bus does."""
    new, ref = Reassembler(), ReferenceReassembler()

    def same(got: list, want: list) -> None:
        assert got == want  # Frame and BadFrame compare by class and value
        assert new.decoder.stats == ref.decoder.stats
        assert new.decoder.pending == ref.decoder.pending
        # white-box, so a divergence shows when it happens, not only once a later CAN frame exposes it
        if new._want:  # fast path: the reference holds the same regular candidate, as announced
            assert new._buf and ref._held == new._buf
            assert ref._starts == list(range(0, len(ref._held), 8))
            header = bytes(ref._held[:12])
            assert new._want == (RULES.frame_length(header) if len(header) == 12 else -1)
        else:  # general path: the same held bytes and CAN frame starts
            assert (new._held, new._starts) == (ref._held, ref._starts)

    for op in [*ops, "flush"]:
        if op == "reset":
            new.reset()
            ref.reset()
            same([], [])
        elif op == "flush":
            same(new.flush(), ref.flush())
        else:
            for arb_id, data in op:
                same(new.feed(arb_id, data), ref.feed(arb_id, data))
    assert new.decoder.pending == 0


# --- candump -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ("  can0  222   [8]  AA 1A 00 03 00 00 00 00", (0x222, bytes.fromhex("AA1A000300000000"))),
        (" (1600000000.123456)  can0  223   [2]  97 BE", (0x223, b"\x97\xbe")),
        ("  can0  RX - -  222   [3]  01 02 03", (0x222, b"\x01\x02\x03")),
        ("  can0  222   [2]  AA 1A   '..'", (0x222, b"\xaa\x1a")),
        ("(1.0) can0 222#AA1A000300000000", (0x222, bytes.fromhex("AA1A000300000000"))),
        ("(1700000000.000001) vcan0 223#97BE", (0x223, b"\x97\xbe")),
        ("can0 222#", (0x222, b"")),
        ("(1.0) can0 222##1AA1A", (0x222, b"\xaa\x1a")),
        ("(1.0) can0 222#R", None),
        ("(1.0) can0 222#AA1", None),
        ("  can0  222   [8]  AA 1A", None),
        ("  can0  222   [8]  remote request", None),
        ("", None),
        ("# comment", None),
    ],
)
def test_parse_line(line: str, expected: tuple[int, bytes] | None) -> None:
    assert parse_line(line) == expected


def _screen(parts: list[tuple[int, bytes]]) -> str:
    return "\n".join(f"  can0  {i:03X}   [{len(d)}]  " + " ".join(f"{b:02X}" for b in d) for i, d in parts)


def _log(parts: list[tuple[int, bytes]]) -> str:
    return "\n".join(f"({k}.000000) can0 {i:03X}#{d.hex().upper()}" for k, (i, d) in enumerate(parts))


@pytest.mark.parametrize("fmt", [_screen, _log])
def test_candump_to_frames(fmt) -> None:
    parts = [*segment(SAMPLE), (0x300, b"\x01"), *segment(SAMPLE, GIMBAL_TX_ID)]
    assert parse_lines(fmt(parts) + "\nnot a frame\n") == parts


def test_decode_can_lines_pairs_command_and_legacy_reply() -> None:
    parts = describe.encode_can("get_angle", 0x31, {"ctrl_byte": 2})
    parts += describe.encode_can(
        "get_angle",
        0x31,
        {"return_code": 0, "data_type": 2, "yaw": 1, "roll": 2, "pitch": 3},
        reply=True,
        legacy=True,
    )
    assert {i for i, _ in parts} == {HOST_TX_ID, GIMBAL_TX_ID}
    for fmt in (_screen, _log):
        out = describe.decode_can_lines(fmt(parts))
        json.dumps(out)
        assert [(d["can_id"], d["command"], d["is_reply"]) for d in out] == [
            (HOST_TX_ID, "get_angle", False),
            (GIMBAL_TX_ID, "get_angle", True),
        ]
        assert out[1]["legacy"] and out[1]["fields"]["data_type"] == 2
        assert describe.decode_bytes(fmt(parts).encode(), can=True) == out


def test_decode_can_lines_reports_truncated_frames() -> None:
    parts = segment(SAMPLE, GIMBAL_TX_ID)[:2]
    (d,) = describe.decode_can_lines(_log(parts))
    assert not d["valid"] and d["error"] == "truncated" and d["can_id"] == GIMBAL_TX_ID


def test_encode_can_ids() -> None:
    parts = describe.encode_can(
        "position_control",
        0x1122,
        {"yaw_angle": 0x20, "roll_angle": 0x30, "pitch_angle": 0x40, "ctrl_byte": 1, "time_for_action": 20},
    )
    assert parts == segment(SAMPLE)
    rep = describe.encode_can("position_control", 1, {"return_code": 0}, reply=True)
    assert {i for i, _ in rep} == {GIMBAL_TX_ID}
    assert {i for i, _ in describe.encode_can("get_angle", 1, {"ctrl_byte": 1}, arb_id=0x100)} == {0x100}
