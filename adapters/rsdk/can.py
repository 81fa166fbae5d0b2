"""R SDK frames over CAN (seed 000 §3.1, PROTOCOL-NOTES): segmentation and reassembly, sans-I/O.

A frame is cut into consecutive CAN payloads of at most 8 bytes with no extra header; every frame
starts at byte 0 of a new CAN frame and a CAN frame never carries bytes of two frames. The host
sends on 0x223 and receives on 0x222 (the seed's first table is the gimbal's view); the gimbal
simulator uses the mirror image, so both ids are parameters. CAN frames are plain
``(arbitration_id, bytes)`` tuples: this module must not know python-can or any bus.
"""

from __future__ import annotations

from adapters.rsdk.protocol import SOF, BadFrame, Decoder, Frame, FrameRules

__all__ = ["CAN_MTU", "GIMBAL_TX_ID", "HOST_TX_ID", "Reassembler", "segment"]

HOST_TX_ID = 0x223  # host -> gimbal
GIMBAL_TX_ID = 0x222  # gimbal -> host
CAN_MTU = 8  # classic CAN payload
_HEADER_LEN = FrameRules.header_len
_NO_HEADER = -1  # Reassembler._want: a regular candidate whose header is not complete yet


def segment(frame: bytes, arb_id: int = HOST_TX_ID) -> list[tuple[int, bytes]]:
    """Cut one encoded R SDK frame into CAN frames on ``arb_id`` (8, 8, ..., rest)."""
    return [(arb_id, bytes(frame[i : i + CAN_MTU])) for i in range(0, len(frame), CAN_MTU)]


class Reassembler:
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

    __slots__ = ("_buf", "_decoder", "_held", "_rules", "_starts", "_want", "rx_id")

    def __init__(self, rx_id: int = GIMBAL_TX_ID) -> None:
        self.rx_id = rx_id
        self._decoder = Decoder()
        self._rules = FrameRules()
        self._held = bytearray()  # copy of the decoder's pending bytes (the candidate frame)
        self._starts: list[int] = []  # offsets in _held where a CAN frame began
        # The fast path (see feed). _want != 0 while the candidate is regular so far: it began with 0xAA
        # at byte 0 of a CAN frame and came in full CAN frames; _want is its announced length once its
        # header is held and valid (_NO_HEADER before). It is all the decoder holds, and _held/_starts
        # are empty. Its bytes go straight into the decoder's buffer, unscanned (a scan would only
        # have returned []), so the decoder's ``pending`` stays exact. _buf is that buffer: the same
        # bytearray for the decoder's life (StreamDecoder only extends, deletes from or clears it).
        self._buf = self._decoder._buf
        self._want = 0

    @property
    def decoder(self) -> Decoder:
        """The underlying stream decoder (for its ``stats``)."""
        return self._decoder

    def feed(self, arb_id: int, data: bytes | bytearray) -> list[Frame | BadFrame]:
        if arb_id != self.rx_id:
            return []
        # Fast path: a regular frame costs an append per CAN frame, a header check at its second and a
        # parse at its last. Each branch returns what the general path below would return (in the
        # comments: why); anything else hands the candidate over to it (_leave_fast).
        n = len(data)
        want = self._want
        if want > 0:
            buf = self._buf
            missing = want - len(buf)
            if n == CAN_MTU and missing > CAN_MTU:
                # rule 3 lets even an 0xAA CAN frame continue; the decoder would wait for the length
                buf += data
                return []
            if n == missing and n <= CAN_MTU:  # the last CAN frame (rule 3 lets an 0xAA one finish it)
                return self._complete(data)
            self._leave_fast()
        elif want:  # the second CAN frame completes the header (rule 4 lets an 0xAA one continue)
            if n == CAN_MTU:
                length = self._rules.frame_length(bytes(self._buf) + bytes(data[: _HEADER_LEN - CAN_MTU]))
                if not isinstance(length, str) and length > 2 * CAN_MTU:  # always: a frame is >= 17
                    self._want = length  # the decoder would check the header and wait for the length
                    self._buf += data
                    return []
            self._leave_fast()
        elif n == CAN_MTU and data[0] == SOF and not self._held:
            # nothing held, so the decoder holds nothing either; it would keep this SOF and wait
            self._buf += data
            self._want = _NO_HEADER
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
        self._want = 0
        self._held.clear()
        self._starts.clear()
        return self._decoder.flush()

    def reset(self) -> None:
        """Forget held bytes (bus reopened); counters are kept."""
        self._want = 0
        self._decoder.reset()
        self._held.clear()
        self._starts.clear()

    def _complete(self, data: bytes | bytearray) -> list[Frame | BadFrame]:
        """The fast path's candidate has its announced length. The decoder would scan it from its SOF,
        check the same header and parse the whole; parse here, and only if that fails let the decoder
        scan (so the failure and any frame behind the SOF come out exactly as on the general path),
        then leave held bytes and CAN frame starts as the general path's ``_trim`` would."""
        self._want = 0
        buf = self._buf
        frame = self._rules.parse(bytes(buf) + data)
        if not isinstance(frame, str):
            buf.clear()
            self._decoder.stats.frames += 1
            return [frame]
        total = len(buf) + len(data)
        out = self._decoder.feed(data)
        pending = self._decoder.pending
        if pending:
            drop = total - pending
            self._held += buf
            self._starts = [s - drop for s in range(0, total, CAN_MTU) if s >= drop]
        return out

    def _leave_fast(self) -> None:
        """Hand the fast path's candidate to the general path, with held bytes and CAN frame starts
        as the general path would have them (the decoder holds the same bytes either way)."""
        self._want = 0
        self._held += self._buf
        self._starts = list(range(0, len(self._buf), CAN_MTU))

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
