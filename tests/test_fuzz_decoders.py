"""Every stream decoder under mutated valid frames (bit flips, cuts, duplications, insertions): nothing
raises, nothing stalls (after flush every byte is accounted for), and untouched frames are still found."""

from __future__ import annotations

from collections.abc import Callable

from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.osdk import protocol as osdk
from adapters.robomaster import protocol as rm
from adapters.rsdk import protocol as rsdk
from adapters.wire.stream import BadFrame
from tests import fuzz_stats

FRAMES: dict[str, tuple[Callable[[], object], list[bytes]]] = {
    "rsdk": (
        rsdk.Decoder,
        [
            bytes.fromhex("AA1A0003000000002211A2420E0020003000400001147B4097BE"),
            rsdk.encode_frame(0x0E, 0x08, bytes(22), 7, cmd_type=0),
            rsdk.encode_frame(0x0D, 0x00, b"\x01\x00", 9),
        ],
    ),
    "osdk": (
        osdk.Decoder,
        [
            osdk.encode_command(0x03, 0x12, b"\x00", 2, 5),
            osdk.encode_ack(2, 5, b"\x00"),
            osdk.encode_frame(b"", session=2, seq=1, is_ack=True),  # header-only (12 bytes, no CRC32)
        ],
    ),
    "robomaster": (
        rm.Decoder,
        [
            bytes.fromhex("A5050000F6000068656C6C6F5634"),
            rm.encode_frame(0x0203, bytes(12), 3),
            rm.encode_frame(0x0201, bytes(13), 4),
        ],
    ),
}


SIZE: dict[str, Callable[[object], bytes]] = {
    "rsdk": lambda f: rsdk.encode(f),  # type: ignore[arg-type]
    "osdk": lambda f: f.encode(),  # type: ignore[attr-defined]
    "robomaster": lambda f: rm.encode_frame(f.cmd_id, f.data, f.seq),  # type: ignore[attr-defined]
}


@st.composite
def mutated_stream(draw: st.DrawFn, family: str) -> tuple[bytes, int]:
    """A stream of valid frames, some mutated; returns it and how many frames were left intact."""
    _, frames = FRAMES[family]
    out = bytearray()
    intact = 0
    for _ in range(draw(st.integers(1, 8))):
        frame = bytearray(draw(st.sampled_from(frames)))
        action = draw(st.sampled_from(["keep", "flip", "cut", "dup", "insert"]))
        if action == "flip":
            i = draw(st.integers(0, len(frame) - 1))
            frame[i] ^= 1 << draw(st.integers(0, 7))
        elif action == "cut":
            frame = frame[: draw(st.integers(0, len(frame) - 1))]
        elif action == "dup":
            frame = frame + frame
            intact += 2
        elif action == "insert":
            i = draw(st.integers(0, len(frame)))
            frame[i:i] = draw(st.binary(min_size=1, max_size=6))
        else:
            intact += 1
        out += frame
    return bytes(out), intact


@settings(max_examples=300)
@given(st.sampled_from(sorted(FRAMES)), st.data())
def test_mutated_frames_never_break_a_decoder(family: str, data: st.DataObject) -> None:
    stream, intact = data.draw(mutated_stream(family))
    chunk = data.draw(st.integers(1, 64))
    decoder = FRAMES[family][0]()
    events = []
    for i in range(0, len(stream), chunk):
        events += decoder.feed(stream[i : i + chunk])  # type: ignore[attr-defined]
    events += decoder.flush()  # type: ignore[attr-defined]
    assert decoder.pending == 0  # type: ignore[attr-defined]
    fuzz_stats.count(f"decoder-{family}")
    frames = [e for e in events if not isinstance(e, BadFrame)]
    # every input byte is accounted for: in a decoded frame or in a BadFrame, none twice, none lost
    dropped = sum(len(e.raw) for e in events if isinstance(e, BadFrame))
    assert dropped + sum(len(SIZE[family](f)) for f in frames) == len(stream)
    if intact == 0:
        return
    assert frames  # at least one intact frame survives its mutated neighbours
