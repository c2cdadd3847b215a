"""CRC-8 SAE J1850 and the end-to-end (E2E) protection of the suspid frames.

The scheme follows AUTOSAR E2E profile 1 (P01) in spirit:

* byte 0 of every protected frame is a CRC-8/SAE-J1850 (polynomial 0x1D, initial value
  0xFF, final XOR 0xFF, no reflection; check value ``crc8_j1850(b"123456789") == 0x4B``)
  computed over the *data ID* -- the 11-bit CAN identifier, low byte then high byte, so a
  frame delivered under a wrong ID fails -- followed by bytes 1 .. DLC-1 of the payload;
* the low nibble of byte 1 is an alive counter 0..14 (0xF is invalid, as in P01) that the
  sender increments per transmission (sensor frames: per sample tick) and the receiver
  checks for repetition and jumps.
"""
from __future__ import annotations

from typing import Final

import numpy as np

#: generator polynomial of CRC-8 SAE J1850 (x^8 + x^4 + x^3 + x^2 + 1)
POLY: Final = 0x1D
#: initial value and final XOR of CRC-8 SAE J1850
INIT: Final = 0xFF
XOR_OUT: Final = 0xFF
#: E2E P01 counter modulus: the counter runs 0..14; 15 is invalid
COUNTER_MODULUS: Final = 15


def _make_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ POLY) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return tuple(table)


#: CRC-8 SAE J1850 lookup table: ``TABLE[crc ^ byte]`` is the next register value
TABLE: Final[tuple[int, ...]] = _make_table()


def crc8_j1850(data: bytes | bytearray | memoryview, init: int = INIT) -> int:
    """CRC-8 SAE J1850 of ``data`` (0..255, final XOR applied) from register ``init``."""
    crc = init
    table = TABLE
    for b in data:
        crc = table[crc ^ b]
    return crc ^ XOR_OUT


def data_id_register(data_id: int) -> int:
    """CRC register after the two data-ID bytes (low, high): the per-ID start value, precomputed
    by receivers once per CAN ID."""
    crc = TABLE[INIT ^ (data_id & 0xFF)]
    return TABLE[crc ^ ((data_id >> 8) & 0xFF)]


def e2e_crc(data_id: int, payload: bytes | bytearray | memoryview) -> int:
    """E2E CRC of a frame: CRC-8 J1850 over the data ID (the 11-bit CAN ID, low byte then
    high byte) and ``payload[1:]`` (byte 0, the CRC slot, skipped)."""
    crc = data_id_register(data_id)
    table = TABLE
    for b in payload[1:]:
        crc = table[crc ^ b]
    return crc ^ XOR_OUT


def e2e_protect(payload: bytearray, data_id: int, counter: int) -> bytearray:
    """Write the alive counter (``counter`` mod 15, low nibble of byte 1) and the CRC (byte 0)
    into ``payload`` (at least 2 bytes) in place and return it."""
    if len(payload) < 2:
        raise ValueError(f"E2E protection needs at least 2 payload bytes, got {len(payload)}")
    payload[1] = (payload[1] & 0xF0) | (counter % COUNTER_MODULUS)
    payload[0] = e2e_crc(data_id, payload)
    return payload


def e2e_check(payload: bytes | bytearray | memoryview, data_id: int) -> bool:
    """``True`` if byte 0 of ``payload`` is the E2E CRC of the frame and the counter is valid."""
    if len(payload) < 2 or (payload[1] & 0x0F) >= COUNTER_MODULUS:
        return False
    return payload[0] == e2e_crc(data_id, payload)


#: :data:`TABLE` as a NumPy array (an ``np.take`` index for CRCs of many frames at once)
TABLE_NP: Final[np.ndarray] = np.array(TABLE, dtype=np.uint8)
