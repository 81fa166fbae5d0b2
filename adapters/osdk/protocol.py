"""DJI Onboard SDK open-protocol framing, plus the session rules (who ACKs what, retransmission,
duplicate suppression) as pure data and logic.

Frame (PROTOCOL-NOTES "DJI Onboard SDK open protocol"; the R SDK frame header)::

    0      SOF 0xAA
    1..2   u16 LE: length[9:0] (whole frame incl. both CRCs) | version[15:10] (0)
    3      session[4:0] | ack<<5 | reserved[7:6] (0)
    4      padding[4:0] | enc[7:5]
    5..7   reserved, 0
    8..9   u16 LE seq
    10..11 u16 LE CRC16 (crc16_rsdk) over bytes 0..9
    12..   data: CmdSet, CmdID, payload on command frames; the raw ACK value on ACK frames
    -4..   u32 LE CRC32 (crc32_rsdk) over every byte before it; absent on header-only frames

A frame with no data is exactly 12 bytes and has no CRC32. The 10-bit length field cannot say more
than 1023, which is below the notes' 1024-byte maximum, so the field is the bound.

Encryption (enc != 0: AES-256-ECB over the data, PROTOCOL-NOTES) is not implemented: the standard
library has no AES and the default configuration is enc = 0. Encrypted frames decode to a
:class:`~adapters.wire.stream.BadFrame` "encrypted frame, no key configured".

The header, both CRCs and the header checks are the R SDK's and live in ``adapters.wire.dji_frame``
(shared with ``adapters/rsdk``); this module adds the OSDK rules (header-only frames, reserved bits
zero, its minimum length and its wording of reasons) and :class:`Frame`.

Owns: frame encode/decode, the stream rules, :class:`SessionTable` (sender: session allocation, the
stored frame for retransmission, ACK matching, deadlines) and :class:`DuplicateFilter` (receiver).
Must not know command ids or payloads (``commands.py``) nor read a clock: time comes in as a value.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Generic, TypeVar

from adapters.errors import FrameError, SessionsExhausted
from adapters.wire.dji_frame import (
    BAD_HEADER_CRC,
    BAD_SOF,
    BAD_VERSION,
    CRC32_LEN,
    FLAG_BIT,
    HEADER_LEN,
    MAX_FRAME_LEN,
    SOF,
    TOO_SHORT,
    HeaderRules,
    build_frame,
    crc32_ok,
    header_crc_ok,
    read_header,
)
from adapters.wire.stream import BadFrame, StreamDecoder

__all__ = [
    "CRC32_LEN",
    "ENCRYPTED_REASON",
    "FIRST_REQUIRED_SESSION",
    "HEADER_LEN",
    "LAST_SESSION",
    "MAX_FRAME_LEN",
    "SOF",
    "BadFrame",
    "Decoder",
    "DuplicateFilter",
    "Frame",
    "FrameRules",
    "Pending",
    "PollResult",
    "RxVerdict",
    "SentFrame",
    "SessionMode",
    "SessionTable",
    "decode_frame",
    "encode_ack",
    "encode_command",
    "encode_frame",
]

# SOF, HEADER_LEN, CRC32_LEN and MAX_FRAME_LEN come from adapters.wire.dji_frame. MAX_FRAME_LEN is
# 0x3FF, what the 10-bit length field can say (notes: max 1024).
MIN_DATA_FRAME_LEN = HEADER_LEN + CRC32_LEN  # 16: a CRC32 with empty data, as OSDK's receiver accepts
FIRST_REQUIRED_SESSION = 2
LAST_SESSION = 31
ENCRYPTED_REASON = "encrypted frame, no key configured"


@dataclass(frozen=True, slots=True)
class Frame:
    """One CRC-checked frame. ``data`` is everything between header and CRC32: CmdSet, CmdID and payload
    on command frames, the bare ACK value on ACK frames (which carry no CmdSet/CmdID)."""

    session: int
    is_ack: bool
    seq: int
    data: bytes
    enc: int = 0
    padding: int = 0

    @property
    def cmd_set(self) -> int | None:
        return None if self.is_ack or len(self.data) < 2 else self.data[0]

    @property
    def cmd_id(self) -> int | None:
        return None if self.is_ack or len(self.data) < 2 else self.data[1]

    @property
    def payload(self) -> bytes:
        """The command's payload (after CmdSet/CmdID), or the ACK value."""
        return self.data if self.is_ack else self.data[2:]

    def encode(self) -> bytes:
        return encode_frame(self.data, session=self.session, seq=self.seq, is_ack=self.is_ack)


def _check_session_seq(session: int, seq: int) -> None:
    if not 0 <= session <= LAST_SESSION:
        raise FrameError(f"session {session} outside 0..{LAST_SESSION}")
    if not 0 <= seq <= 0xFFFF:
        raise FrameError(f"seq {seq} outside 0..0xFFFF")


def encode_frame(data: bytes | bytearray, *, session: int, seq: int, is_ack: bool = False) -> bytes:
    """The complete wire frame (enc 0). Empty ``data`` gives the 12-byte header-only frame."""
    _check_session_seq(session, seq)
    length = HEADER_LEN if not data else HEADER_LEN + len(data) + CRC32_LEN
    if length > MAX_FRAME_LEN:
        raise FrameError(f"frame would be {length} bytes; the length field holds at most {MAX_FRAME_LEN}")
    return build_frame(session | (FLAG_BIT if is_ack else 0), 0, seq, data)


def encode_command(cmd_set: int, cmd_id: int, payload: bytes | bytearray, session: int, seq: int) -> bytes:
    """A command frame: data = CmdSet, CmdID, payload."""
    if not (0 <= cmd_set <= 0xFF and 0 <= cmd_id <= 0xFF):
        raise FrameError(f"cmd_set/cmd_id 0x{cmd_set:X}/0x{cmd_id:X} must be bytes")
    return encode_frame(bytes((cmd_set, cmd_id)) + bytes(payload), session=session, seq=seq)


def encode_ack(session: int, seq: int, ack_bytes: bytes | bytearray) -> bytes:
    """An ACK frame answering the command sent on ``session`` with ``seq``: data = the raw ACK value."""
    return encode_frame(ack_bytes, session=session, seq=seq, is_ack=True)


class FrameRules(HeaderRules):
    """Receive validation for :class:`~adapters.wire.stream.StreamDecoder`: SOF, header CRC, version 0,
    reserved bits and bytes zero, a possible length (12, or 16 and more); then CRC32 and the
    encryption flag. The header checks are the shared :class:`~adapters.wire.dji_frame.HeaderRules`."""

    def __init__(self) -> None:
        super().__init__(min_len=MIN_DATA_FRAME_LEN, header_only=True, reserved_zero=True)

    def frame_length(self, header: bytes) -> int | str:
        if header[0] != SOF:
            return BAD_SOF
        n = super().frame_length(header)
        if isinstance(n, str):
            # Error path only. The shared checks run cheapest first; this receiver reports a bad
            # header CRC ahead of anything else (every other field of such a header is noise), and
            # says which version or length it saw.
            if not header_crc_ok(header):
                return BAD_HEADER_CRC
            word = header[1] | (header[2] << 8)
            if n == BAD_VERSION:
                return f"version {word >> 10}"
            if n == TOO_SHORT:
                return f"bad length {word}"
        return n

    def parse(self, frame: bytes) -> Frame | str:
        if len(frame) == HEADER_LEN:
            data = b""
        else:
            if not crc32_ok(frame):
                return "frame crc"
            data = frame[HEADER_LEN:-CRC32_LEN]
        h = read_header(frame)
        enc, padding = h.enc >> 5, h.enc & 0x1F
        if enc:
            return ENCRYPTED_REASON
        if not h.flag and len(data) < 2:
            return "command frame without CmdSet/CmdID"
        return Frame(h.type_bits, h.flag, h.seq, bytes(data), enc, padding)


class Decoder(StreamDecoder[Frame]):
    """Stream decoder for OSDK frames: ``feed(bytes)`` -> frames and BadFrames; ``flush()`` at idle."""

    __slots__ = ()

    def __init__(self) -> None:
        super().__init__(FrameRules())


def decode_frame(raw: bytes) -> Frame:
    """Exactly one complete frame, or :class:`FrameError` saying why not."""
    rules = FrameRules()
    if len(raw) < HEADER_LEN or raw[0] != SOF:
        raise FrameError("not a frame: too short or no SOF")
    n = rules.frame_length(raw[:HEADER_LEN])
    if isinstance(n, str):
        raise FrameError(n)
    if n != len(raw):
        raise FrameError(f"header announces {n} bytes, got {len(raw)}")
    res = rules.parse(raw)
    if isinstance(res, str):
        raise FrameError(res)
    return res


# --------------------------------------------------------------------------------------------------
# Sessions (sans-I/O: the caller passes ``now`` as a float, in seconds of any monotonic clock)


class SessionMode(IntEnum):
    """What the sender wants back (PROTOCOL-NOTES "Sessions")."""

    NO_ACK = 0  # session 0
    ACK_TOLERANT = 1  # session 1: an ACK is wanted, its loss tolerated (never resent)
    ACK_REQUIRED = 2  # sessions 2..31: resend the same frame on timeout


@dataclass(frozen=True, slots=True)
class SentFrame:
    """What to write to the link for a new command."""

    frame: bytes
    session: int
    seq: int


#: what the sender attaches to a command to find its waiter again (the adapter: a future and the name)
TagT = TypeVar("TagT")


@dataclass(slots=True)
class Pending(Generic[TagT]):
    """A command waiting for its ACK; ``frame`` is resent unchanged (same session, same seq)."""

    session: int
    seq: int
    cmd_set: int
    cmd_id: int
    frame: bytes
    deadline: float
    timeout: float
    retries_left: int
    tag: TagT | None = None


@dataclass(frozen=True, slots=True)
class PollResult(Generic[TagT]):
    """Frames to write again now, and commands that ran out of retries (answer them with a timeout)."""

    resend: tuple[bytes, ...] = ()
    expired: tuple[Pending[TagT], ...] = ()


class SessionTable(Generic[TagT]):
    """Sender side: one global seq incremented per new command, sessions 2..31 handed out round-robin
    to commands that need an ACK, their frames kept for retransmission, ACKs matched by
    ``(session, seq)`` (the only safe key: ACK frames carry no CmdSet/CmdID)."""

    __slots__ = ("_next_session", "_pending", "_seq")

    def __init__(self, first_seq: int = 0) -> None:
        self._seq = first_seq & 0xFFFF
        self._next_session = FIRST_REQUIRED_SESSION
        self._pending: dict[tuple[int, int], Pending[TagT]] = {}

    def next_seq(self) -> int:
        seq = self._seq
        self._seq = (seq + 1) & 0xFFFF
        return seq

    def _allocate(self) -> int:
        busy = {s for s, _ in self._pending if s >= FIRST_REQUIRED_SESSION}
        n = LAST_SESSION - FIRST_REQUIRED_SESSION + 1
        for k in range(n):
            s = FIRST_REQUIRED_SESSION + (self._next_session - FIRST_REQUIRED_SESSION + k) % n
            if s not in busy:
                self._next_session = FIRST_REQUIRED_SESSION + (s - FIRST_REQUIRED_SESSION + 1) % n
                return s
        raise SessionsExhausted("all sessions 2..31 are waiting for an ACK")

    def send(
        self,
        cmd_set: int,
        cmd_id: int,
        payload: bytes,
        *,
        now: float,
        mode: SessionMode = SessionMode.ACK_REQUIRED,
        timeout: float = 0.5,
        retries: int = 2,
        tag: TagT | None = None,
    ) -> SentFrame:
        """Frame a new command. Modes 1 and 2 are remembered until ACKed or expired; mode 1 is never
        resent (``retries`` is ignored), mode 2 is resent ``retries`` times, ``timeout`` apart."""
        session = {SessionMode.NO_ACK: 0, SessionMode.ACK_TOLERANT: 1}.get(mode)
        if session is None:
            session = self._allocate()
        seq = self.next_seq()
        frame = encode_command(cmd_set, cmd_id, payload, session, seq)
        if mode != SessionMode.NO_ACK:
            left = retries if mode == SessionMode.ACK_REQUIRED else 0
            self._pending[(session, seq)] = Pending(
                session, seq, cmd_set, cmd_id, frame, now + timeout, timeout, left, tag
            )
        return SentFrame(frame, session, seq)

    def on_ack(self, frame: Frame) -> Pending[TagT] | None:
        """The command this ACK answers (and forget it), or None for a late or unknown ACK."""
        if not frame.is_ack:
            return None
        return self._pending.pop((frame.session, frame.seq), None)

    def poll(self, now: float) -> PollResult[TagT]:
        """Resend what is due, expire what has no retries left. Call at :meth:`next_deadline`."""
        resend: list[bytes] = []
        expired: list[Pending[TagT]] = []
        for key, p in list(self._pending.items()):
            if p.deadline > now:
                continue
            if p.retries_left > 0:
                p.retries_left -= 1
                p.deadline = now + p.timeout
                resend.append(p.frame)
            else:
                expired.append(self._pending.pop(key))
        return PollResult(tuple(resend), tuple(expired))

    def next_deadline(self) -> float | None:
        return min((p.deadline for p in self._pending.values()), default=None)

    @property
    def pending(self) -> tuple[Pending[TagT], ...]:
        return tuple(self._pending.values())

    def clear(self) -> tuple[Pending[TagT], ...]:
        """Drop everything (link closed); returns what was waiting so the caller can fail it."""
        dropped = tuple(self._pending.values())
        self._pending.clear()
        return dropped


@dataclass(frozen=True, slots=True)
class RxVerdict:
    """Receiver's answer for one incoming command: act on it, or it is a retransmission (send
    ``resend``, the stored ACK, if there is one yet; never act twice)."""

    duplicate: bool
    resend: bytes | None = None


class DuplicateFilter:
    """Receiver side: remembers the last seq and the ACK frame sent per session >= 1, so a resent
    command (same session, same seq) gets the stored ACK again instead of being executed twice."""

    __slots__ = ("_last",)

    def __init__(self) -> None:
        self._last: dict[int, tuple[int, bytes | None]] = {}

    def check(self, frame: Frame) -> RxVerdict:
        if frame.is_ack or frame.session == 0:
            return RxVerdict(False)
        last = self._last.get(frame.session)
        if last is not None and last[0] == frame.seq:
            return RxVerdict(True, last[1])
        self._last[frame.session] = (frame.seq, None)
        return RxVerdict(False)

    def ack(self, frame: Frame, ack_bytes: bytes) -> bytes:
        """The ACK frame for ``frame`` (same session and seq), stored for retransmissions."""
        out = encode_ack(frame.session, frame.seq, ack_bytes)
        last = self._last.get(frame.session)
        if frame.session and last is not None and last[0] == frame.seq:
            self._last[frame.session] = (frame.seq, out)
        return out

    def reset(self) -> None:
        self._last.clear()
