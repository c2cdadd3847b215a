"""CRC-8 SAE J1850 and the E2E protection."""
from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from suspid.can.crc import crc8_j1850, e2e_check, e2e_crc, e2e_protect


def _crc_bitwise(data: bytes) -> int:
    """Reference: bit-by-bit CRC-8 SAE J1850 (poly 0x1D, init 0xFF, xorout 0xFF)."""
    crc = 0xFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF


def test_check_value():
    # catalogued check value of CRC-8/SAE-J1850
    assert crc8_j1850(b"123456789") == 0x4B


@given(st.binary(max_size=64))
def test_table_equals_bitwise(data):
    assert crc8_j1850(data) == _crc_bitwise(data)


def test_e2e_crc_covers_data_id():
    payload = bytearray(8)
    a = e2e_crc(0x110, payload)
    assert a == _crc_bitwise(bytes([0x10, 0x01]) + bytes(7))
    assert e2e_crc(0x111, payload) != a  # same payload under another ID fails


@settings(max_examples=60)
@given(st.binary(min_size=2, max_size=8), st.integers(0, 0x7FF), st.integers(0, 100))
def test_protect_then_every_single_bit_flip_detected(raw, data_id, counter):
    data = e2e_protect(bytearray(raw), data_id, counter)
    assert data[1] & 0x0F == counter % 15
    assert e2e_check(data, data_id)
    for bit in range(8 * len(data)):
        bad = bytearray(data)
        bad[bit // 8] ^= 1 << (bit % 8)
        assert not e2e_check(bad, data_id), f"bit {bit} flip not detected"


def test_counter_value_15_is_invalid():
    data = e2e_protect(bytearray(8), 0x100, 0)
    data[1] |= 0x0F
    data[0] = e2e_crc(0x100, data)  # a correct CRC does not make counter 15 valid
    assert not e2e_check(data, 0x100)

