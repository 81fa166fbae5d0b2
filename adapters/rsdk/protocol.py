"""DJI R SDK framing (seed 000 §2.1-2.2, §3.3-3.4): bytes <-> :class:`Frame`, and a stream decoder.

Frame layout (all little-endian)::

    0  SOF 0xAA
    1  u16 length | version << 10      length = the whole frame, both CRCs included; version 0
    3  CmdType   bits 4:0 reply type (0 none, 1 optional, 2-31 required), bit 5 reply frame
    4  ENC       bits 4:0 padding, bits 7:5 encryption type (0 = none)
    5  3 reserved bytes
    8  u16 SEQ   opaque; the gimbal echoes it in its reply (the only safe reply key)
    10 u16 CRC16 over bytes 0..9
    12 data      CmdSet, CmdID, payload (latest reply form; legacy replies lack CmdSet/CmdID)
    -4 u32 CRC32 over everything before it

The header, both CRCs and the header checks are shared with the Onboard SDK frame and live in
``adapters.wire.dji_frame``; this module adds the R SDK rules (minimum lengths, data required, the
reply formats) and :class:`Frame`.

Owns the frame layer only: it must not know what a command's payload means (that is
``commands.py``), nor CAN (``can.py``), nor any I/O. Standard library and ``adapters.wire`` only.

Reply frames and the two reply formats (PROTOCOL-NOTES): since protocol revision 2.2.0.5 a reply's
data starts with CmdSet/CmdID ("latest"); older firmware omits them ("legacy", 2 bytes shorter). The
frame layer cannot tell which, so a decoded reply carries the data split *as if latest* whenever it
has at least 2 bytes, and ``cmd_set``/``cmd_id`` are ``None`` only for a 1-byte data segment (a legacy
bare return code, 17-byte frame). ``Frame.data`` always gives the raw data segment back;
``commands.decode_reply`` settles the format against the command that was sent (matched by SEQ).
"""

from __future__ import annotations

from dataclasses import dataclass

from adapters.wire.dji_frame import (
    CRC32_LEN,
    FLAG_BIT,
    HEADER_LEN,
    MAX_FRAME_LEN,
    SOF,
    TYPE_MASK,
    HeaderRules,
    build_frame,
    crc16_fast,
    crc32_ok,
)
from adapters.wire.stream import BadFrame, StreamDecoder

__all__ = [
    "HEADER_LEN",
    "MAX_FRAME_LEN",
    "MIN_COMMAND_LEN",
    "MIN_REPLY_LEN",
    "SOF",
    "BadFrame",
    "Decoder",
    "Frame",
    "FrameRules",
    "crc16_fast",
    "encode",
    "encode_frame",
]

# SOF, HEADER_LEN, CRC32_LEN, MAX_FRAME_LEN and crc16_fast are adapters.wire.dji_frame's, re-exported.
# A command frame always carries CmdSet and CmdID: 12 + 2 + 4. A legacy reply may be a bare return
# code with no CmdSet/CmdID (ArduPilot's driver expects exactly 17 bytes for those), so replies may be
# one byte shorter: a single minimum of 18 would drop every legacy position/speed reply.
MIN_COMMAND_LEN = HEADER_LEN + 2 + CRC32_LEN
MIN_REPLY_LEN = HEADER_LEN + 1 + CRC32_LEN
REPLY_BIT = FLAG_BIT
DEFAULT_CMD_TYPE = 0x03  # "reply required" (what DJI's samples and real drivers send)


@dataclass(frozen=True, slots=True)
class Frame:
    """One R SDK frame.

    ``cmd_type`` is the CmdType reply type (bits 4:0); ``is_reply`` is CmdType bit 5; ``enc`` the raw
    ENC byte. ``cmd_set``/``cmd_id`` are ``None`` only for a legacy reply whose data segment carries
    no CmdSet/CmdID (see the module docstring): then ``payload`` is the whole data segment."""

    cmd_set: int | None
    cmd_id: int | None
    payload: bytes
    seq: int = 0
    cmd_type: int = DEFAULT_CMD_TYPE
    is_reply: bool = False
    enc: int = 0

    @property
    def data(self) -> bytes:
        """The raw data segment as on the wire."""
        if self.cmd_set is None or self.cmd_id is None:
            return self.payload
        return bytes((self.cmd_set, self.cmd_id)) + self.payload

    @property
    def needs_reply(self) -> bool:
        """A command frame whose reply type (2-31) asks the receiver to answer."""
        return not self.is_reply and self.cmd_type >= 2

    @property
    def key(self) -> tuple[int, int] | None:
        """(CmdSet, CmdID) as carried by the frame, None for a bare legacy reply."""
        if self.cmd_set is None or self.cmd_id is None:
            return None
        return (self.cmd_set, self.cmd_id)


# Decoding builds one Frame per frame; the frozen dataclass __init__ goes through object.__setattr__
# per field (about 1.1 us for seven fields, a third of the decoder's per-frame budget). Writing the
# slots through their member descriptors on a bare instance gives the identical object in half the
# time; only the decoder's hot path uses it.
_new_obj = object.__new__
_S0, _S1, _S2, _S3, _S4, _S5, _S6 = (
    getattr(Frame, name).__set__
    for name in ("cmd_set", "cmd_id", "payload", "seq", "cmd_type", "is_reply", "enc")
)
assert Frame.__slots__ == ("cmd_set", "cmd_id", "payload", "seq", "cmd_type", "is_reply", "enc")


def _make_frame(
    cmd_set: int | None, cmd_id: int | None, payload: bytes, seq: int, cmd_type: int, is_reply: bool, enc: int
) -> Frame:
    f = _new_obj(Frame)
    _S0(f, cmd_set)
    _S1(f, cmd_id)
    _S2(f, payload)
    _S3(f, seq)
    _S4(f, cmd_type)
    _S5(f, is_reply)
    _S6(f, enc)
    return f


def encode(frame: Frame) -> bytes:
    """Serialise a frame, computing length, header CRC16 and frame CRC32.

    Raises ValueError for a field out of range or a frame longer than 1023 bytes."""
    if frame.cmd_set is None or frame.cmd_id is None:
        if not frame.is_reply:
            raise ValueError("a command frame must carry CmdSet and CmdID")
        if frame.cmd_set is not None or frame.cmd_id is not None:
            raise ValueError("give both CmdSet and CmdID, or neither (legacy reply)")
    elif not (0 <= frame.cmd_set <= 0xFF and 0 <= frame.cmd_id <= 0xFF):
        raise ValueError(f"CmdSet/CmdID must be bytes, got {frame.cmd_set!r}/{frame.cmd_id!r}")
    if not 0 <= frame.cmd_type <= 0x1F:
        raise ValueError(f"cmd_type (reply type) must be 0..31, got {frame.cmd_type}")
    if not 0 <= frame.seq <= 0xFFFF:
        raise ValueError(f"seq must be 0..65535, got {frame.seq}")
    if not 0 <= frame.enc <= 0xFF:
        raise ValueError(f"enc must be 0..255, got {frame.enc}")
    data = frame.data
    n = HEADER_LEN + len(data) + CRC32_LEN
    if n > MAX_FRAME_LEN:
        raise ValueError(f"frame would be {n} bytes; the length field allows at most {MAX_FRAME_LEN}")
    if not data:
        raise ValueError("a frame needs a data segment")
    return build_frame(frame.cmd_type | (REPLY_BIT if frame.is_reply else 0), frame.enc, frame.seq, data)


def encode_frame(
    cmd_set: int | None,
    cmd_id: int | None,
    payload: bytes,
    seq: int,
    *,
    cmd_type: int = DEFAULT_CMD_TYPE,
    is_reply: bool = False,
    enc: int = 0,
) -> bytes:
    """Shorthand for ``encode(Frame(...))``."""
    return encode(Frame(cmd_set, cmd_id, bytes(payload), seq, cmd_type, is_reply, enc))


class FrameRules(HeaderRules):
    """The R SDK part of :class:`adapters.wire.stream.StreamDecoder`.

    Header checks (shared with the OSDK in :class:`adapters.wire.dji_frame.HeaderRules`, cheapest
    first): version 0, length >= 18 (>= 17 for a reply, see MIN_REPLY_LEN), CRC16; reserved bits are
    not checked and header-only frames do not exist. Then CRC32 at ``length``; an encrypted frame
    (ENC bits 7:5 != 0) is reported, not decoded: no gimbal encrypts and we hold no key."""

    __slots__ = ()

    def __init__(self) -> None:
        super().__init__(
            min_len=MIN_COMMAND_LEN, min_flagged_len=MIN_REPLY_LEN, header_only=False, reserved_zero=False
        )

    def parse(self, frame: bytes) -> Frame | str:
        if not crc32_ok(frame):
            return "frame crc"
        enc = frame[4]
        if enc & 0xE0:
            return "encrypted (unsupported)"
        ct = frame[3]
        n = len(frame)
        if n == MIN_REPLY_LEN:  # only reachable for replies: a bare legacy return code
            return _make_frame(
                None, None, frame[12:13], frame[8] | (frame[9] << 8), ct & TYPE_MASK, True, enc
            )
        # _make_frame inlined: this is the per-frame hot path
        f = _new_obj(Frame)
        _S0(f, frame[12])
        _S1(f, frame[13])
        _S2(f, frame[14 : n - 4])
        _S3(f, frame[8] | (frame[9] << 8))
        _S4(f, ct & TYPE_MASK)
        _S5(f, ct & REPLY_BIT != 0)
        _S6(f, enc)
        return f


class Decoder(StreamDecoder[Frame]):
    """Stream decoder for R SDK frames: ``feed(bytes) -> list[Frame | BadFrame]``, ``flush()`` at idle."""

    __slots__ = ()

    def __init__(self) -> None:
        super().__init__(FrameRules())
