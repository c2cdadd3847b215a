"""E2E protection of a frame: CRC-8 J1850 and the alive counter (AUTOSAR E2E profile 1);
byte 0 is the CRC, the low nibble of byte 1 the counter (see :mod:`suspid.can.crc`)."""
from __future__ import annotations

from typing import Union

import numpy as np

from suspid.can.crc import TABLE_NP, data_id_register

#: a frame payload (python-can gives ``bytearray``, the batch path ``bytes``)
Payload = Union[bytes, bytearray]
#: CRC register after the data-ID bytes of a frame ID (the array check's start value)
crc_start = data_id_register


def alive_counters(rows: np.ndarray) -> np.ndarray:
    """Alive counters (int64) of payloads given as little-endian ``uint64`` (one per frame)."""
    return (rows >> np.uint64(8) & np.uint64(0x0F)).astype(np.int64)


def crc_ok_rows(b8: np.ndarray, start: np.ndarray, dlc: np.ndarray,
                check: np.ndarray) -> np.ndarray:
    """Which frames of payloads ``b8`` (m, 8) pass the E2E CRC (True where not ``check``)."""
    ok = np.ones(b8.shape[0], dtype=bool)
    if not check.any():
        return ok
    crc = start
    lmin = int(dlc[check].min())
    for i in range(1, int(dlc[check].max())):
        nxt = TABLE_NP.take(crc ^ b8[:, i])
        crc = nxt if i < lmin else np.where(dlc > i, nxt, crc)
    return ~(check & ((crc ^ np.uint8(0xFF)) != b8[:, 0]))
