"""E2E protection of a frame: CRC-8 J1850 and the alive counter (AUTOSAR E2E profile 1).

Byte 0 of a protected frame is the CRC-8 SAE J1850 of the data ID (the CAN ID, low byte
then high byte) followed by bytes 1 .. DLC-1; the low nibble of byte 1 is the alive counter
0..14 (see :mod:`suspid.can.crc`).

Scalar: :func:`crc_checker` (one frame, ``bytes``), :func:`alive_counter`.
Arrays: :func:`crc_ok_rows` (many frames of any protected messages, one table lookup per
byte column), :func:`alive_counters` (payloads read as little-endian ``uint64``).
"""
from __future__ import annotations

from typing import Callable, Union

import numpy as np

from suspid.can.crc import TABLE_NP, data_id_register, make_e2e_checker

#: a frame payload (python-can gives ``bytearray``, the batch path ``bytes``)
Payload = Union[bytes, bytearray]


def crc_checker(frame_id: int, dlc: int) -> Callable[[Payload], bool]:
    """``check(payload) -> bool``: the E2E CRC of a ``dlc``-byte frame of ``frame_id`` holds."""
    return make_e2e_checker(frame_id, dlc)


def crc_start(frame_id: int) -> int:
    """CRC register after the data-ID bytes of ``frame_id`` (the array check's start value)."""
    return data_id_register(frame_id)


def alive_counter(data: Payload) -> int:
    """The alive counter (0..15) of one protected payload."""
    return data[1] & 0x0F


def alive_counters(rows: np.ndarray) -> np.ndarray:
    """Alive counters (int64) of payloads given as little-endian ``uint64`` (one per frame)."""
    return (rows >> np.uint64(8) & np.uint64(0x0F)).astype(np.int64)


def crc_ok_rows(b8: np.ndarray, start: np.ndarray, dlc: np.ndarray,
                check: np.ndarray) -> np.ndarray:
    """Which frames pass the E2E CRC (``True`` also where ``check`` is False).

    Parameters
    ----------
    b8 : ndarray of uint8, shape (m, 8)
        Payloads (zero padded).
    start : ndarray of uint8, shape (m,)
        :func:`crc_start` of each frame's ID.
    dlc : ndarray of int, shape (m,)
        Each frame's message length (bytes; at most 8).
    check : ndarray of bool, shape (m,)
        Frames to check (E2E protected and passed the earlier checks).

    Returns
    -------
    ndarray of bool, shape (m,)
        Equal to the scalar :func:`crc_checker` of each checked frame.
    """
    ok = np.ones(b8.shape[0], dtype=bool)
    if not check.any():
        return ok
    crc = start
    lmin = int(dlc[check].min())
    for i in range(1, int(dlc[check].max())):
        nxt = TABLE_NP.take(crc ^ b8[:, i])
        crc = nxt if i < lmin else np.where(dlc > i, nxt, crc)
    return ~(check & ((crc ^ np.uint8(0xFF)) != b8[:, 0]))
