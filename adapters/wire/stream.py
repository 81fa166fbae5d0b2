"""The resynchronising receive buffer shared by every stream decoder.

A byte stream (UART, reassembled CAN) carries frames that start with a fixed SOF byte, have a
header that is checked on its own (CRC8 / CRC16) and announces the frame length, then a body
checked by a second CRC. The receiver hunts the SOF, checks the header, waits for the length, checks
the whole frame, and on any failure shifts one byte past the failed SOF and hunts again, so a
valid frame hidden behind garbage or behind a false SOF is still found.

Each protocol supplies only :class:`FrameRules`; this module owns the loop. Sans-I/O: ``feed``
takes bytes and returns events; ``flush`` is called by the link when the line goes idle (the
classic UART inter-frame timeout), so a false header announcing a long frame cannot hold back
the real frames behind it forever.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar

__all__ = ["BadFrame", "DecoderStats", "FrameRules", "StreamDecoder"]

F = TypeVar("F")
F_co = TypeVar("F_co", covariant=True)


@dataclass(frozen=True, slots=True)
class BadFrame:
    """Bytes the decoder had to drop, and why (``garbage``, ``header crc``, ``frame crc`` …)."""

    reason: str
    raw: bytes


@dataclass(slots=True)
class DecoderStats:
    frames: int = 0
    bad_frames: int = 0
    dropped_bytes: int = 0
    crc_errors: int = 0  # the part of bad_frames whose reason names a CRC (the rest: framing errors)


class FrameRules(Protocol[F_co]):
    """The per-protocol part of a stream decoder."""

    sof: int
    header_len: int

    def frame_length(self, header: bytes) -> int | str:
        """Total frame length announced by a complete header, or the reason the header is bad."""
        ...

    def parse(self, frame: bytes) -> F_co | str:
        """The decoded frame, or the reason the complete frame is bad (e.g. its CRC)."""
        ...


class StreamDecoder(Generic[F]):
    """Feed bytes, get frames and :class:`BadFrame` values, in stream order."""

    __slots__ = ("_buf", "_pos", "_rules", "_want", "stats")

    def __init__(self, rules: FrameRules[F]) -> None:
        self._rules = rules
        self._buf = bytearray()
        self._pos = 0
        self._want = 0  # length of the checked, incomplete candidate at the buffer's start (0: none)
        self.stats = DecoderStats()

    @property
    def pending(self) -> int:
        """Bytes held while waiting for the rest of a frame."""
        return len(self._buf) - self._pos

    def feed(self, data: bytes | bytearray | memoryview) -> list[F | BadFrame]:
        if data:
            self._buf += data
        if len(self._buf) < self._want:
            # the candidate's header was checked already; nothing can complete before its length
            return []
        out: list[F | BadFrame] = []
        self._scan(out)
        return out

    def flush(self) -> list[F | BadFrame]:
        """End of stream (or an idle line): drop incomplete candidates one byte at a time so any
        complete frame behind them is still found; report what could not be decoded."""
        out: list[F | BadFrame] = []
        self._scan(out)
        while self._pos < len(self._buf):
            start = self._pos
            self._pos += 1
            self._scan(out, bad=("truncated", start))
        self._compact()
        return out

    def reset(self) -> None:
        """Forget buffered bytes (a link reopened); counters are kept."""
        self._buf.clear()
        self._pos = 0
        self._want = 0

    def _scan(self, out: list[F | BadFrame], bad: tuple[str, int] | None = None) -> None:
        buf, rules, stats = self._buf, self._rules, self.stats
        sof, hlen = rules.sof, rules.header_len
        pos = self._pos
        self._want = 0
        while True:
            i = buf.find(sof, pos)
            end = len(buf) if i < 0 else i
            if bad is not None:
                # one BadFrame per failed candidate, covering every byte skipped because of it
                reason, start = bad
                out.append(BadFrame(reason, bytes(buf[start:end])))
                stats.bad_frames += 1
                if "crc" in reason:
                    stats.crc_errors += 1
                stats.dropped_bytes += end - start
                bad = None
            elif end > pos:
                out.append(BadFrame("garbage", bytes(buf[pos:end])))
                stats.bad_frames += 1
                stats.dropped_bytes += end - pos
            if i < 0:
                pos = len(buf)
                break
            pos = i
            if len(buf) - pos < hlen:
                break
            n = rules.frame_length(bytes(buf[pos : pos + hlen]))
            if isinstance(n, str):
                bad = (n, pos)
                pos += 1
                continue
            if len(buf) - pos < n:
                self._want = n  # the candidate moves to the buffer's start when compacted
                break
            frame = bytes(buf[pos : pos + n])
            res = rules.parse(frame)
            if isinstance(res, str):
                bad = (res, pos)
                pos += 1
                continue
            out.append(res)
            stats.frames += 1
            pos += n
        self._pos = pos
        self._compact()

    def _compact(self) -> None:
        if self._pos:
            del self._buf[: self._pos]
            self._pos = 0
