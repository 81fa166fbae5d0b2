"""CRC engines for the DJI wire protocols.

R SDK and Onboard SDK frames use a CRC16 (poly 0x8005) and a CRC32 (poly 0x04C11DB7), both
reflected, no final xor, seeded so that the *register* starts at 0x3AA3 (the bit-reverse of the
spec's ``init`` 0xC55C / 0xC55C0000). RoboMaster frames use a CRC8 (poly 0x31 reflected, init 0xFF)
and CRC-16/MCRF4XX (poly 0x1021 reflected, init 0xFFFF).

Why the odd paths: the CRC32 and the RoboMaster CRC16 run in C through ``zlib.crc32`` and
``binascii.crc_hqx`` (the reflected CRC equals the bit-reversed result of the unreflected CRC over
bit-reversed bytes), so decoding stays far above what a saturated CAN bus or UART can deliver.
"""

from __future__ import annotations

import binascii
import zlib

__all__ = ["crc8_rm", "crc16_rm", "crc16_rsdk", "crc32_rsdk"]


def _reflected_table(poly_reflected: int, width: int) -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ poly_reflected if crc & 1 else crc >> 1
        table.append(crc & ((1 << width) - 1))
    return tuple(table)


_CRC16_8005 = _reflected_table(0xA001, 16)  # 0x8005 reflected
_CRC8_31 = _reflected_table(0x8C, 8)  # 0x31 reflected

RSDK_CRC16_SEED = 0x3AA3
RSDK_CRC32_SEED = 0x00003AA3


def crc16_rsdk(data: bytes | bytearray | memoryview, crc: int = RSDK_CRC16_SEED) -> int:
    """Header CRC of R SDK / OSDK frames (seed 000 §3.2: width 16, poly 0x8005, init 0xC55C, refin/refout)."""
    table = _CRC16_8005
    for b in data:
        crc = (crc >> 8) ^ table[(crc ^ b) & 0xFF]
    return crc


def crc32_rsdk(data: bytes | bytearray | memoryview, crc: int = RSDK_CRC32_SEED) -> int:
    """Frame CRC of R SDK / OSDK frames (seed 000 §3.2), computed in C by zlib.

    zlib inverts the register on entry and exit; undoing both gives the raw reflected CRC with
    our seed and no final xor."""
    return zlib.crc32(data, crc ^ 0xFFFFFFFF) ^ 0xFFFFFFFF


def crc8_rm(data: bytes | bytearray | memoryview, crc: int = 0xFF) -> int:
    """RoboMaster header CRC8: poly 0x31 reflected, init 0xFF, no xorout (not CRC-8/MAXIM-DOW)."""
    table = _CRC8_31
    for b in data:
        crc = table[crc ^ b]
    return crc


_REV8 = bytes(int(f"{i:08b}"[::-1], 2) for i in range(256))


def _rev16(x: int) -> int:
    return (_REV8[x & 0xFF] << 8) | _REV8[x >> 8]


def crc16_rm(data: bytes | bytearray | memoryview, crc: int = 0xFFFF) -> int:
    """RoboMaster frame CRC16 = CRC-16/MCRF4XX (poly 0x1021 reflected, init 0xFFFF, no xorout).

    Seed 002 calls its configuration "Kermit"; Kermit starts at 0, this one at 0xFFFF."""
    return _rev16(binascii.crc_hqx(bytes(data).translate(_REV8), _rev16(crc)))
