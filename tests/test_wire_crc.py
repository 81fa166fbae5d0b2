"""CRC engines against the check values in PROTOCOL-NOTES, the seed samples, and a bitwise reference."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from adapters.wire.crc import crc8_rm, crc16_rm, crc16_rsdk, crc32_rsdk

CHECK = b"123456789"


def _bitwise_reflected(data: bytes, poly: int, width: int, init_register: int) -> int:
    """Textbook reflected CRC, one bit at a time: the reference the table engines must equal."""
    crc = init_register
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ poly if crc & 1 else crc >> 1
    return crc & ((1 << width) - 1)


def test_check_values() -> None:
    assert crc16_rsdk(CHECK) == 0x2752
    assert crc32_rsdk(CHECK) == 0xE4D9DC14
    assert crc8_rm(CHECK) == 0x0B
    assert crc16_rm(CHECK) == 0x6F91


def test_rsdk_seed_sample_crcs() -> None:
    # seed 000 §3.3: AA 1A 00 03 00 00 00 00 22 11 | A2 42 | 0E 00 20 00 30 00 40 00 01 14 | 7B 40 97 BE
    frame = bytes.fromhex("AA1A0003000000002211A2420E0020003000400001147B4097BE")
    assert crc16_rsdk(frame[:10]) == 0x42A2
    assert crc32_rsdk(frame[:-4]) == 0xBE97407B


def test_robomaster_hello_crcs() -> None:
    # seed 002 "hello": CRC8 0xF6 over A5 05 00 00, CRC16 bytes 56 34 (little-endian 0x3456)
    assert crc8_rm(bytes([0xA5, 0x05, 0x00, 0x00])) == 0xF6
    assert crc16_rm(bytes([0xA5, 0x05, 0x00, 0x00, 0xF6, 0x00, 0x00]) + b"hello") == 0x3456


def test_robomaster_crcs_differ_from_the_named_standard_variants() -> None:
    # CRC-8/MAXIM-DOW starts at 0 and gives 0xA1; KERMIT starts at 0 and gives 0x2189.
    assert _bitwise_reflected(CHECK, 0x8C, 8, 0x00) == 0xA1
    assert _bitwise_reflected(CHECK, 0x8408, 16, 0x0000) == 0x2189
    assert crc8_rm(CHECK) != 0xA1
    assert crc16_rm(CHECK) != 0x2189


@given(st.binary(max_size=300))
def test_table_engines_equal_bitwise_reference(data: bytes) -> None:
    assert crc16_rsdk(data) == _bitwise_reflected(data, 0xA001, 16, 0x3AA3)
    assert crc32_rsdk(data) == _bitwise_reflected(data, 0xEDB88320, 32, 0x3AA3)
    assert crc8_rm(data) == _bitwise_reflected(data, 0x8C, 8, 0xFF)
    assert crc16_rm(data) == _bitwise_reflected(data, 0x8408, 16, 0xFFFF)


@given(st.binary(max_size=100), st.binary(max_size=100))
def test_crcs_are_incremental(a: bytes, b: bytes) -> None:
    assert crc16_rsdk(b, crc16_rsdk(a)) == crc16_rsdk(a + b)
    assert crc32_rsdk(b, crc32_rsdk(a)) == crc32_rsdk(a + b)
    assert crc8_rm(b, crc8_rm(a)) == crc8_rm(a + b)
    assert crc16_rm(b, crc16_rm(a)) == crc16_rm(a + b)
