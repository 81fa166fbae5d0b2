"""The shared resynchronising buffer, exercised with a minimal protocol so its own rules are visible:
SOF 0x7E, 3-byte header (SOF, length, crc8 of the first two), body, 1-byte sum."""

from __future__ import annotations

from dataclasses import dataclass

from hypothesis import given
from hypothesis import strategies as st

from adapters.errors import LayoutError
from adapters.wire.crc import crc8_rm
from adapters.wire.layout import Field, Layout, Tail
from adapters.wire.stream import BadFrame, StreamDecoder


@dataclass(frozen=True, slots=True)
class Toy:
    body: bytes


class ToyRules:
    sof = 0x7E
    header_len = 3

    def frame_length(self, header: bytes) -> int | str:
        if crc8_rm(header[:2]) != header[2]:
            return "header crc"
        return 3 + header[1] + 1

    def parse(self, frame: bytes) -> Toy | str:
        if sum(frame[3:-1]) & 0xFF != frame[-1]:
            return "frame sum"
        return Toy(frame[3:-1])


def toy(body: bytes) -> bytes:
    head = bytes([0x7E, len(body)])
    return head + bytes([crc8_rm(head)]) + body + bytes([sum(body) & 0xFF])


def frames(events: list[Toy | BadFrame]) -> list[bytes]:
    return [e.body for e in events if isinstance(e, Toy)]


def test_garbage_is_reported_once_and_frames_survive() -> None:
    d = StreamDecoder(ToyRules())
    out = d.feed(b"\x01\x02" + toy(b"abc") + b"\x03" + toy(b"d"))
    assert frames(out) == [b"abc", b"d"]
    assert [e.reason for e in out if isinstance(e, BadFrame)] == ["garbage", "garbage"]
    assert d.stats.frames == 2 and d.stats.dropped_bytes == 3


def test_false_sof_inside_garbage_is_skipped() -> None:
    d = StreamDecoder(ToyRules())
    out = d.feed(b"\x7e\x05\x00" + toy(b"xyz"))
    assert frames(out) == [b"xyz"]
    bad = [e for e in out if isinstance(e, BadFrame)]
    assert bad == [BadFrame("header crc", b"\x7e\x05\x00")]


def test_corrupt_body_reports_and_rescans() -> None:
    good = toy(b"hello")
    broken = bytearray(toy(b"world"))
    broken[5] ^= 0xFF
    d = StreamDecoder(ToyRules())
    out = d.feed(bytes(broken) + good)
    assert frames(out) == [b"hello"]
    assert [e.reason for e in out if isinstance(e, BadFrame)] == ["frame sum"]


def test_long_false_header_is_released_by_flush() -> None:
    # a header that passes its check and announces 200 bytes hides the real frame until the line idles
    head = bytes([0x7E, 200])
    fake = head + bytes([crc8_rm(head)])
    d = StreamDecoder(ToyRules())
    assert frames(d.feed(fake + toy(b"ok"))) == []
    assert d.pending > 0
    out = d.flush()
    assert frames(out) == [b"ok"]
    assert d.pending == 0


@given(st.lists(st.binary(max_size=40), max_size=6), st.binary(max_size=64), st.data())
def test_any_split_finds_every_frame_after_garbage(bodies: list[bytes], garbage: bytes, data) -> None:
    stream = garbage + b"".join(toy(b) for b in bodies)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=8)))
    d = StreamDecoder(ToyRules())
    out: list[Toy | BadFrame] = []
    last = 0
    for c in [*cuts, len(stream)]:
        out += d.feed(stream[last:c])
        last = c
    out += d.flush()
    got = frames(out)
    # garbage may itself contain a valid toy frame, so the real frames are the tail of what was found
    assert got[len(got) - len(bodies) :] == bodies
    assert d.pending == 0


@given(st.binary(max_size=2000))
def test_random_bytes_never_raise_or_stall(blob: bytes) -> None:
    d = StreamDecoder(ToyRules())
    d.feed(blob)
    d.flush()
    assert d.pending == 0


def test_layout_round_trip_and_errors() -> None:
    lay = Layout(
        [
            Field("a", "h", minimum=-10, maximum=10),
            Field("b", "B", count=3),
            Field("c", "f"),
            Field("s", "s", 4),
        ],
        tail=Tail("rest"),
    )
    raw = lay.encode({"a": -2, "b": [1, 2], "c": 0.5, "s": b"ab", "rest": b"\x01\x02"})
    assert (
        raw == bytes.fromhex("feff") + bytes([1, 2, 0]) + bytes.fromhex("0000003f") + b"ab\0\0" + b"\x01\x02"
    )
    assert lay.decode(raw) == {"a": -2, "b": [1, 2, 0], "c": 0.5, "s": b"ab\0\0", "rest": b"\x01\x02"}
    for bad in ({"a": 40000}, {"b": [1, 2, 3, 4]}, {"c": float("nan")}, {"zz": 1}, {"a": 1.5}):
        try:
            lay.encode(bad)
        except LayoutError:
            continue
        raise AssertionError(f"{bad} was accepted")
    fixed = Layout([Field("x", "I")])
    assert fixed.size == 4
    for wrong in (b"", b"\0" * 3, b"\0" * 5):
        try:
            fixed.decode(wrong)
        except LayoutError:
            continue
        raise AssertionError(f"{wrong!r} decoded")
