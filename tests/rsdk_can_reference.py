"""A verbatim copy of ``adapters.rsdk.can.Reassembler`` as it was before its fast path (commit 74e9a65),
kept as the oracle for the equivalence property test in ``tests/test_rsdk_can.py``: the optimised class
must return the same items and counters for every input. Do not "fix" this copy; it is the spec."""

from __future__ import annotations

from adapters.rsdk.can import CAN_MTU, GIMBAL_TX_ID
from adapters.rsdk.protocol import SOF, BadFrame, Decoder, Frame, FrameRules

__all__ = ["ReferenceReassembler"]


class ReferenceReassembler:
    """Rebuild R SDK frames from the CAN frames of one id: ``feed(arb_id, data) -> list[Frame | BadFrame]``.

    CAN payloads on ``rx_id`` are fed, in order, to a byte-stream :class:`~adapters.rsdk.protocol.Decoder`
    (hunt 0xAA, CRC16 at 12 bytes, CRC32 at the announced length, resync on failure); other ids are
    ignored. On top of that, the segmentation rule lets a lost CAN frame be noticed early:

    **Restart rule.** When a CAN frame whose first byte is 0xAA arrives while an incomplete candidate
    frame is held, and that CAN frame *cannot* be the candidate's continuation, the candidate is
    declared failed before the CAN frame is fed: its SOF byte is dropped (BadFrame "incomplete frame",
    together with any garbage up to the next SOF) and the held bytes are rescanned, exactly as after a
    failed CRC, so a frame that began inside them (at a later CAN frame) becomes the candidate; the
    check repeats against it. It cannot be a continuation when any of these holds:

    1. the candidate did not start at byte 0 of a CAN frame (a false SOF found while resyncing);
    2. the candidate already took in a short (< 8 byte) CAN frame, which only ever ends a frame;
    3. the candidate's header is complete and the CAN frame is longer than the bytes still missing
       (it would straddle two frames), or shorter than 8 bytes without finishing it exactly;
    4. the header is incomplete and the CAN frame is shorter than 8 bytes (a frame is >= 17 bytes,
       so its second CAN frame is always full).

    Otherwise (an 8-byte CAN frame, or one finishing the candidate exactly) 0xAA may be ordinary data
    and the bytes stay with the candidate; if it was in fact a new frame after a lost CAN frame, the
    candidate fails its CRC32 once its announced length is reached and the stream decoder rescans,
    finding the new frame at its own start. A candidate that lost one CAN frame lacks at most 8
    bytes and a frame is at least 17, so after a single loss the next frame is still reported when
    its own last CAN frame arrives (the tests pin this); after several losses it may come later, at
    the latest on :meth:`flush`, which the link calls at end of input or when the bus goes idle.
    Every frame whose CAN frames all arrived is reported, in order.
    """

    __slots__ = ("_decoder", "_held", "_rules", "_starts", "rx_id")

    def __init__(self, rx_id: int = GIMBAL_TX_ID) -> None:
        self.rx_id = rx_id
        self._decoder = Decoder()
        self._rules = FrameRules()
        self._held = bytearray()  # copy of the decoder's pending bytes (the candidate frame)
        self._starts: list[int] = []  # offsets in _held where a CAN frame began

    @property
    def decoder(self) -> Decoder:
        """The underlying stream decoder (for its ``stats``)."""
        return self._decoder

    def feed(self, arb_id: int, data: bytes | bytearray) -> list[Frame | BadFrame]:
        if arb_id != self.rx_id:
            return []
        data = bytes(data)
        if len(data) > CAN_MTU:
            return [BadFrame("CAN frame longer than 8 bytes", data)]
        held = self._held
        if held and data and data[0] == SOF:
            out: list[Frame | BadFrame] = []
            while held and not self._may_continue(len(data)):
                self._restart(out)
            out += self._decoder.feed(data)
        else:
            out = self._decoder.feed(data)
        self._starts.append(len(held))
        held += data
        # the common cases without _trim's list rebuild: a frame just completed (nothing pending), or
        # the decoder holds exactly what we hold
        pending = self._decoder.pending
        if pending == 0:
            held.clear()
            self._starts.clear()
        elif pending != len(held):
            self._trim()
        return out

    def flush(self) -> list[Frame | BadFrame]:
        """End of input or idle bus: report held bytes, finding any complete frame among them."""
        self._held.clear()
        self._starts.clear()
        return self._decoder.flush()

    def reset(self) -> None:
        """Forget held bytes (bus reopened); counters are kept."""
        self._decoder.reset()
        self._held.clear()
        self._starts.clear()

    def _trim(self) -> None:
        """Keep ``_held`` equal to the decoder's pending bytes, ``_starts`` to CAN frame starts in it."""
        drop = len(self._held) - self._decoder.pending
        if drop:
            del self._held[:drop]
            self._starts = [s - drop for s in self._starts if s >= drop]

    def _restart(self, out: list[Frame | BadFrame]) -> None:
        """Fail the held candidate: drop its SOF and rescan the rest of the held bytes."""
        old = bytes(self._held)
        dec = self._decoder
        dec.reset()
        items = dec.feed(old[1:])
        first = items[0] if items else None
        if isinstance(first, BadFrame) and first.reason == "garbage":
            items[0] = BadFrame("incomplete frame", old[:1] + first.raw)
        else:
            items.insert(0, BadFrame("incomplete frame", old[:1]))
            dec.stats.bad_frames += 1
        dec.stats.dropped_bytes += 1
        out += items
        del self._held[:1]
        self._starts = [s - 1 for s in self._starts if s >= 1]
        self._trim()

    def _may_continue(self, n: int) -> bool:
        held = self._held
        h = len(held)
        starts = self._starts
        if not starts or starts[0] != 0:
            return False  # rule 1: the candidate does not begin at a CAN frame start
        if any(b - a < CAN_MTU for a, b in zip(starts, [*starts[1:], h], strict=True)):
            return False  # rule 2: a short CAN frame inside the candidate
        if h < self._rules.header_len:
            return n == CAN_MTU  # rule 4
        length = self._rules.frame_length(bytes(held[: self._rules.header_len]))
        if isinstance(length, str):  # cannot happen: the decoder only holds valid headers
            return False
        missing = length - h
        return n == missing or (n == CAN_MTU and missing > CAN_MTU)  # rule 3
