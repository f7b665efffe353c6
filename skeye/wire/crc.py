"""Checksums of the vehicle packet protocol (docs/protocols/packets.md).

How this works: frames carry ``crc16`` of their payload, the AscTec reflected CCITT variant
(polynomial 0x1021 processed LSB first, register starting at 0x00FF, no final xor), computed
byte by byte exactly as the AscTec firmware does. The CTRL_INPUT and WAYPOINT commands instead
carry ``command_checksum``: a plain 16-bit sum of their fields plus 0xAAAA. Both return an
unsigned 16-bit value; the wire stores it little-endian.
"""

from __future__ import annotations

CRC16_INIT = 0x00FF
COMMAND_CHECKSUM_OFFSET = 0xAAAA


def crc16(data: bytes) -> int:
    """CRC16 of ``data`` as AscTec computes it; ``crc16(b"123456789") == 0x9DB8``."""
    crc = CRC16_INIT
    for byte in data:
        d = byte ^ (crc & 0xFF)
        d ^= (d << 4) & 0xFF
        crc = (((d << 8) | (crc >> 8)) ^ (d >> 4) ^ (d << 3)) & 0xFFFF
    return crc


def command_checksum(*fields: int) -> int:
    """16-bit sum of ``fields`` plus 0xAAAA, wrapping (signed fields count as two's complement)."""
    return (sum(fields) + COMMAND_CHECKSUM_OFFSET) & 0xFFFF
