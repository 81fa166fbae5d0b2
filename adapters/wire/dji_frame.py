"""The frame envelope shared by the DJI R SDK and the Onboard SDK open protocol.

Both protocols use the same 12-byte header, CRCs and trailer (all little-endian)::

    0      SOF 0xAA
    1..2   u16 length | version << 10   length = the whole frame, both CRCs included; version 0
    3      bits 4:0 R SDK reply type / OSDK session; bit 5 R SDK reply / OSDK ack (``FLAG_BIT``);
           bits 7:6 reserved
    4      ENC: bits 4:0 padding, bits 7:5 encryption type
    5..7   reserved
    8..9   u16 seq
    10..11 u16 CRC16 (crc16_rsdk) over bytes 0..9
    12..   data
    -4..   u32 CRC32 (crc32_rsdk) over everything before it; OSDK header-only frames (12 bytes) have none

Owns: header packing, header validation (:class:`HeaderRules`, parametrised by what the two protocols
differ in: minimum lengths, header-only frames, reserved bits), the fast header CRC16 and the CRC32
check/append. Must not know what byte 3's bits mean to either protocol, what the data holds, or any
I/O; the adapters (``adapters/rsdk/protocol.py``, ``adapters/osdk/protocol.py``) own that.
Standard library and ``adapters.wire`` only.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable
from typing import NamedTuple

from adapters.wire.crc import RSDK_CRC16_SEED, RSDK_CRC32_SEED, crc16_rsdk

__all__ = [
    "BAD_HEADER_CRC",
    "BAD_RESERVED",
    "BAD_SOF",
    "BAD_VERSION",
    "CRC16_T8",
    "CRC16_T16",
    "CRC32_LEN",
    "FLAG_BIT",
    "HEADER_LEN",
    "MAX_FRAME_LEN",
    "SHORT_HEADER",
    "SOF",
    "TOO_SHORT",
    "TYPE_MASK",
    "Header",
    "HeaderRules",
    "build_frame",
    "crc16_fast",
    "crc32_ok",
    "header_crc16",
    "header_crc_ok",
    "pack_header",
    "read_header",
    "seal_crc32",
]

SOF = 0xAA
HEADER_LEN = 12
CRC32_LEN = 4
MAX_FRAME_LEN = 0x3FF  # the length field has 10 bits; a larger word means a non-zero version
TYPE_MASK = 0x1F  # byte 3 bits 4:0
FLAG_BIT = 0x20  # byte 3 bit 5
_RESERVED_BITS = 0xC0  # byte 3 bits 7:6

# Reasons returned by HeaderRules (the R SDK's historical wording; the OSDK adapter rewords two).
BAD_SOF = "sof"
SHORT_HEADER = "short header"
BAD_VERSION = "version not 0"
BAD_RESERVED = "reserved bits set"
TOO_SHORT = "length too short"
BAD_HEADER_CRC = "header crc"

# --- fast CRC16 ---------------------------------------------------------------------------------
# The header CRC runs once per candidate SOF, so it is the hot spot of a stream decoder. The CRC
# register is 16 bits wide, so two input bytes XOR-ed into it are fully shifted out by one
# 65536-entry table step: half the Python-level iterations of the byte table. The table is derived
# from the shared engine (crc16_rsdk with a zero register returns the byte table), and a test pins
# the equivalence.
CRC16_T8: list[int] = [crc16_rsdk(bytes((i,)), 0) for i in range(256)]
CRC16_T16: list[int] = [
    (CRC16_T8[x & 0xFF] >> 8) ^ CRC16_T8[((x >> 8) ^ CRC16_T8[x & 0xFF]) & 0xFF] for x in range(0x10000)
]
_T8 = CRC16_T8
_T16 = CRC16_T16
_SEED16 = RSDK_CRC16_SEED
_HDR_WORDS = struct.Struct("<6H").unpack_from  # bytes 0..11, stored CRC16 included
_HEAD10_WORDS: Callable[[bytes | bytearray], tuple[int, int, int, int, int]] = struct.Struct(
    "<5H"
).unpack_from  # bytes 0..9
_PACK_HEAD = struct.Struct("<BHBB3xHH").pack_into  # SOF, length, byte 3, ENC, reserved, seq, CRC16
_PACK_U32 = struct.Struct("<I").pack_into
_READ_HEAD = struct.Struct("<xHBB3xH").unpack_from  # length word, byte 3, ENC, seq


def crc16_fast(data: bytes | bytearray | memoryview, crc: int = _SEED16) -> int:
    """Same result as ``adapters.wire.crc.crc16_rsdk``, two bytes per table step."""
    t = _T16
    n = len(data)
    even = n & ~1
    for (w,) in struct.iter_unpack("<H", data[:even]):
        crc = t[crc ^ w]
    if n & 1:
        crc = (crc >> 8) ^ _T8[(crc ^ data[-1]) & 0xFF]
    return crc


def header_crc16(buf: bytes | bytearray) -> int:
    """CRC16 of header bytes 0..9 (what bytes 10..11 must hold); ``buf`` may be longer."""
    t = _T16
    w0, w1, w2, w3, w4 = _HEAD10_WORDS(buf)
    return t[t[t[t[t[w0 ^ _SEED16] ^ w1] ^ w2] ^ w3] ^ w4]


def header_crc_ok(header: bytes | bytearray) -> bool:
    """The stored CRC16 matches bytes 0..9.

    A reflected CRC without final xor leaves a zero register after its own little-endian value, so
    the CRC over all 12 bytes is 0 exactly when the stored one is right (one step is a bijection of
    the register, so no other stored value reaches 0)."""
    t = _T16
    w0, w1, w2, w3, w4, w5 = _HDR_WORDS(header)
    return not t[t[t[t[t[t[w0 ^ _SEED16] ^ w1] ^ w2] ^ w3] ^ w4] ^ w5]


# --- CRC32 --------------------------------------------------------------------------------------
# zlib inverts the register on entry and exit (see adapters.wire.crc). As for the CRC16, a frame
# followed by its own CRC32 leaves a zero register: after zlib's exit inversion that is 0xFFFFFFFF,
# so checking needs no slicing off of the trailing CRC.
_Z_SEED = RSDK_CRC32_SEED ^ 0xFFFFFFFF
_Z_OK = 0xFFFFFFFF
_zcrc = zlib.crc32


def crc32_ok(frame: bytes | bytearray | memoryview) -> bool:
    """The trailing u32 LE CRC32 matches everything before it (``frame`` holds at least 4 bytes)."""
    return _zcrc(frame, _Z_SEED) == _Z_OK


def seal_crc32(buf: bytearray) -> None:
    """Write the CRC32 of ``buf[:-4]`` into the last 4 bytes of ``buf``."""
    n = len(buf) - CRC32_LEN
    _PACK_U32(buf, n, _zcrc(memoryview(buf)[:n], _Z_SEED) ^ 0xFFFFFFFF)


# --- header -------------------------------------------------------------------------------------


def pack_header(buf: bytearray, length: int, type_byte: int, enc: int, seq: int) -> None:
    """Write the 12 header bytes (version 0, reserved zero, CRC16) at the start of ``buf``.

    Callers validate their fields first (with their own messages); out-of-range values raise
    ``struct.error``."""
    _PACK_HEAD(buf, 0, SOF, length, type_byte, enc, seq, 0)
    crc = header_crc16(buf)
    buf[10] = crc & 0xFF
    buf[11] = crc >> 8


def build_frame(type_byte: int, enc: int, seq: int, data: bytes | bytearray) -> bytes:
    """A complete frame: header, ``data``, CRC32; empty ``data`` gives the 12-byte header-only frame.

    Callers check their own rules first (ranges, ``MAX_FRAME_LEN``, whether data is required)."""
    if not data:
        buf = bytearray(HEADER_LEN)
        pack_header(buf, HEADER_LEN, type_byte, enc, seq)
        return bytes(buf)
    n = HEADER_LEN + len(data) + CRC32_LEN
    buf = bytearray(n)
    pack_header(buf, n, type_byte, enc, seq)
    buf[HEADER_LEN : n - CRC32_LEN] = data
    seal_crc32(buf)
    return bytes(buf)


class Header(NamedTuple):
    """The header's fields. ``type_bits``: byte 3 bits 4:0 (R SDK reply type, OSDK session);
    ``flag``: byte 3 bit 5 (R SDK reply, OSDK ack); ``enc``: the raw byte 4 (padding | enc << 5)."""

    length: int
    version: int
    type_bits: int
    flag: bool
    enc: int
    seq: int


def read_header(buf: bytes | bytearray) -> Header:
    """The fields of the header at the start of ``buf``, unchecked."""
    word, b3, enc, seq = _READ_HEAD(buf)
    return Header(word & MAX_FRAME_LEN, word >> 10, b3 & TYPE_MASK, bool(b3 & FLAG_BIT), enc, seq)


class HeaderRules:
    """Header validation for :class:`adapters.wire.stream.StreamDecoder`, parametrised by what the two
    protocols differ in; an adapter's ``FrameRules`` subclasses it and adds ``parse``.

    ``min_len`` applies when byte 3 bit 5 is clear, ``min_flagged_len`` when it is set (an R SDK
    legacy reply may be one byte shorter than any command); ``header_only`` also allows a 12-byte
    frame with no data and no CRC32 (OSDK); ``reserved_zero`` rejects non-zero byte 3 bits 7:6 and
    bytes 5..7 (OSDK).

    Checks run cheapest first (version, reserved, length, then CRC16), so most false SOFs cost no
    CRC. The 10-bit length field caps frames at 1023 bytes, so no maximum check is needed."""

    __slots__ = ("_max_min_len", "header_only", "min_flagged_len", "min_len", "reserved_zero")
    sof = SOF
    header_len = HEADER_LEN

    def __init__(
        self, *, min_len: int, min_flagged_len: int | None = None, header_only: bool, reserved_zero: bool
    ) -> None:
        self.min_len = min_len
        self.min_flagged_len = min_len if min_flagged_len is None else min_flagged_len
        self.header_only = header_only
        self.reserved_zero = reserved_zero
        self._max_min_len = max(self.min_len, self.min_flagged_len)  # one comparison for most frames

    def frame_length(self, header: bytes) -> int | str:
        """The announced frame length, or why the header is bad. The stream decoder only hands over
        headers that start with SOF, so SOF is not checked here (see :meth:`parse_header`)."""
        v = header[1] | (header[2] << 8)
        if v > MAX_FRAME_LEN:
            return BAD_VERSION
        if self.reserved_zero and (header[3] & _RESERVED_BITS or header[5] or header[6] or header[7]):
            return BAD_RESERVED
        if (
            v < self._max_min_len
            and v < (self.min_flagged_len if header[3] & FLAG_BIT else self.min_len)
            and not (v == HEADER_LEN and self.header_only)
        ):
            return TOO_SHORT
        t = _T16
        w0, w1, w2, w3, w4, w5 = _HDR_WORDS(header)
        # header_crc_ok inlined: this runs once per candidate SOF
        if t[t[t[t[t[t[w0 ^ _SEED16] ^ w1] ^ w2] ^ w3] ^ w4] ^ w5]:
            return BAD_HEADER_CRC
        return v

    def parse_header(self, header: bytes | bytearray) -> Header | str:
        """The fields of a header at the start of ``header`` (SOF checked too), or why it is bad."""
        if len(header) < HEADER_LEN:
            return SHORT_HEADER
        if header[0] != SOF:
            return BAD_SOF
        n = self.frame_length(bytes(header[:HEADER_LEN]))
        if isinstance(n, str):
            return n
        return read_header(header)
