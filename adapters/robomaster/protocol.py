"""RoboMaster "DJI serial" framing (seed 002): the 0xA5 frame the referee system and Taproot's
``DJISerial`` speak over UART.

Frame layout (all little-endian)::

    0      SOF 0xA5
    1..2   u16 data length (the body only)
    3      u8 seq (nobody checks it on this link; count gaps for link-quality metrics only)
    4      CRC8 over bytes 0..3
    5..6   u16 cmd_id
    7..    data (data length bytes)
    -2..   u16 CRC16 over every byte before it

CRC names: the seed's Python calls its configurations "MAXIM_DOW" and "KERMIT". The *parameters*
it gives are right, the names are not: the CRC8 is poly 0x31 reflected with init **0xFF** (CRC-8/MAXIM-DOW
starts at 0; check "123456789" -> 0x0B), and the CRC16 is exactly **CRC-16/MCRF4XX** (poly 0x1021
reflected, init 0xFFFF; KERMIT starts at 0; check -> 0x6F91). Both live in ``adapters.wire.crc``.
The seed's own CRC16 example lists the body as ``68 65 6C 6F`` (one ``6C`` short); the CRC 0x3456
is over the real ``hello`` body, which is what we reproduce.

Owns: framing, the stream decoder rules and the size presets. Must not know command ids, payload
layouts or protocol seasons (that is ``commands.py``). Sans-I/O: bytes in, frames out.
"""

from __future__ import annotations

from dataclasses import dataclass

from adapters.wire.crc import crc8_rm, crc16_rm
from adapters.wire.stream import BadFrame, StreamDecoder

__all__ = [
    "CRC16_LEN",
    "DEFAULT_MAX_DATA_LEN",
    "FRAME_OVERHEAD",
    "HEADER_LEN",
    "REFEREE_MAX_DATA_LEN",
    "REFEREE_MAX_FRAME_LEN",
    "SOF",
    "BadFrame",
    "Decoder",
    "Frame",
    "FrameRules",
    "encode_frame",
]

SOF = 0xA5
HEADER_LEN = 5  # SOF, u16 length, seq, CRC8
CMD_ID_LEN = 2
CRC16_LEN = 2
FRAME_OVERHEAD = HEADER_LEN + CMD_ID_LEN + CRC16_LEN  # 9 bytes around the data
MAX_WIRE_DATA_LEN = 0xFFFF  # what the u16 length field can say

# Taproot's DJISerial receive buffer (SERIAL_RX_BUFF_SIZE, seed 002): the generous default.
DEFAULT_MAX_DATA_LEN = 1024
# The referee system's normal link never sends a frame over 128 bytes (PROTOCOL-NOTES); a tighter
# bound lets a corrupted length field that passed CRC8 by chance be dropped at once instead of
# holding back the frames behind it until the line idles.
REFEREE_MAX_FRAME_LEN = 128
REFEREE_MAX_DATA_LEN = REFEREE_MAX_FRAME_LEN - FRAME_OVERHEAD  # 119


@dataclass(frozen=True, slots=True)
class Frame:
    """One CRC-checked frame: ``data`` is the body after the cmd_id, without the CRC16."""

    seq: int
    cmd_id: int
    data: bytes


def encode_frame(cmd_id: int, data: bytes | bytearray = b"", seq: int = 0) -> bytes:
    """The complete wire frame for ``cmd_id`` carrying ``data`` (the caller owns ``seq``)."""
    if not 0 <= cmd_id <= 0xFFFF:
        raise ValueError(f"cmd_id {cmd_id} outside 0..0xFFFF")
    if not 0 <= seq <= 0xFF:
        raise ValueError(f"seq {seq} outside 0..255")
    if len(data) > MAX_WIRE_DATA_LEN:
        raise ValueError(f"data is {len(data)} bytes; the length field holds at most {MAX_WIRE_DATA_LEN}")
    head = bytearray((SOF, len(data) & 0xFF, len(data) >> 8, seq))
    head.append(crc8_rm(head))
    body = head + cmd_id.to_bytes(2, "little") + bytes(data)
    return bytes(body + crc16_rm(body).to_bytes(2, "little"))


class FrameRules:
    """The per-protocol part of :class:`adapters.wire.stream.StreamDecoder` for 0xA5 frames."""

    sof = SOF
    header_len = HEADER_LEN

    __slots__ = ("max_data_len",)

    def __init__(self, max_data_len: int = DEFAULT_MAX_DATA_LEN) -> None:
        if not 0 <= max_data_len <= MAX_WIRE_DATA_LEN:
            raise ValueError(f"max_data_len {max_data_len} outside 0..{MAX_WIRE_DATA_LEN}")
        self.max_data_len = max_data_len

    def frame_length(self, header: bytes) -> int | str:
        if crc8_rm(header[:4]) != header[4]:
            return "header crc"
        n = header[1] | header[2] << 8
        if n > self.max_data_len:
            return "data too long"
        return FRAME_OVERHEAD + n

    def parse(self, frame: bytes) -> Frame | str:
        if crc16_rm(frame[:-2]) != (frame[-2] | frame[-1] << 8):
            return "frame crc"
        return Frame(seq=frame[3], cmd_id=frame[5] | frame[6] << 8, data=frame[HEADER_LEN + CMD_ID_LEN : -2])


class Decoder(StreamDecoder[Frame]):
    """Resynchronising 0xA5 stream decoder: ``feed`` bytes, get :class:`Frame` and ``BadFrame`` values.

    ``max_data_len`` bounds the length field: 1024 (Taproot's buffer) by default, or
    ``REFEREE_MAX_DATA_LEN`` (119) on a referee-system link."""

    __slots__ = ()

    def __init__(self, max_data_len: int = DEFAULT_MAX_DATA_LEN) -> None:
        super().__init__(FrameRules(max_data_len))
