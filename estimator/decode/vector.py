"""Array versions of the decoder's per-frame signal extraction (the batch path): on ``(m, 8)``
payloads, strided views or shifts and masks, then the scalar code's operations in its order,
so every value is bit for bit the scalar one; other layouts return ``None`` (frame by frame).
"""
from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np
from cantools.database.can import Message

from suspid.can.codec import MessageCodec, SignalSpec, signal_spec
from suspid.can.signal_map import SignalMapping

#: ``rows (m, 8) uint8 -> raw values (m,)``: int64 for integer signals, float64 for floats
RawFn = Callable[[np.ndarray], np.ndarray]
#: ``rows (m, 8) uint8 -> values (m, k) float64, one column per mapping``
RowsFn = Callable[[np.ndarray], np.ndarray]

#: widest integer signal decoded with arrays (every raw value exact in a double)
MAX_BITS = 52


def _strided(rows: np.ndarray, offset: int, dtype: str) -> np.ndarray:
    """Column view ``rows[:, offset:offset+size]`` reinterpreted as one ``dtype`` per row."""
    m = rows.shape[0]
    return np.ndarray((m,), dtype=np.dtype(dtype), buffer=rows, offset=offset,
                      strides=(rows.strides[0],))


def compile_raw(spec: SignalSpec, length: int) -> RawFn | None:
    """Raw values ``(m,)`` of one signal from payloads ``(m, 8)``; None without an array form."""
    if length > 8:
        return None
    if spec.is_float:
        if spec.big_endian or spec.start % 8 or spec.length not in (32, 64):
            return None
        off, code = spec.start // 8, f"<f{spec.length // 8}"
        return lambda rows: _strided(rows, off, code).astype(np.float64)
    if spec.length > MAX_BITS:
        return None
    if not spec.big_endian and spec.start % 8 == 0 and spec.length in (8, 16, 32):
        off = spec.start // 8
        code = f"<{'i' if spec.signed else 'u'}{spec.length // 8}"
        return lambda rows: _strided(rows, off, code).astype(np.int64)
    shift = np.uint64(spec.start)
    mask = np.uint64((1 << spec.length) - 1)
    sign = (1 << (spec.length - 1)) if spec.signed else 0
    be_shift = np.uint64(8 * (8 - length))

    def raw(rows: np.ndarray) -> np.ndarray:
        m = rows.shape[0]
        if spec.big_endian:   # int.from_bytes(payload, "big") of the message's length
            word = rows.view(">u8").reshape(m).astype(np.uint64) >> be_shift
        else:                 # int.from_bytes(payload, "little"): zero padding is harmless
            word = rows.view("<u8").reshape(m)
        r = ((word >> shift) & mask).astype(np.int64)
        if sign:
            r -= (r & sign) << 1
        return r

    return raw


def compile_vector_row(msg: Message, maps: Sequence[SignalMapping]) -> RowsFn | None:
    """Array twin of the scalar row function of one data message: ``f(rows (m, 8) uint8)
    -> values (m, k)``, one column per mapping of ``maps``, bit for bit the scalar values;
    ``None`` without an exact array form. A factor ``1.0`` and an offset ``-0.0`` stand in
    for the operations the scalar code skips (they change no double)."""
    if msg.length > 8:
        return None
    names = list(dict.fromkeys(m.signal for m in maps))
    codec = MessageCodec(msg, names)
    specs = codec.specs
    maybe = [compile_raw(s, msg.length) for s in specs]
    raws = [r for r in maybe if r is not None]
    if len(raws) < len(maybe):
        return None
    k = len(specs)
    # one view for all signals when they are integers of one width at multiples of it
    widths = {s.length for s in specs}
    view_code = None
    view_cols: list[int] = []
    if (len(widths) == 1 and not any(s.is_float or s.big_endian for s in specs)
            and specs[0].length in (8, 16, 32)
            and len({s.signed for s in specs}) == 1
            and all(s.start % s.length == 0 for s in specs)):
        w = specs[0].length
        view_code = f"<{'i' if specs[0].signed else 'u'}{w // 8}"
        view_cols = [s.start // w for s in specs]
    # MessageCodec._scale_term: DBC scale and offset, the same skips (floats not scaled)
    dbc_scale = np.array([1.0 if s.is_float or (s.scale == 1.0 and s.offset == 0.0)
                          else s.scale for s in specs])
    dbc_off = np.array([s.offset if not s.is_float and s.offset != 0.0 else -0.0
                        for s in specs])
    any_dbc_scale = bool((dbc_scale != 1.0).any())
    any_dbc_off = any(not s.is_float and s.offset != 0.0 for s in specs)
    index = [names.index(m.signal) for m in maps]
    identity = index == list(range(k))
    map_scale = np.array([float(m.scale) for m in maps])
    map_off = np.array([float(m.offset) if not m.remove_mean and float(m.offset) != 0.0
                        else -0.0 for m in maps])
    any_map_scale = bool((map_scale != 1.0).any())
    any_map_off = any(not m.remove_mean and float(m.offset) != 0.0 for m in maps)
    # validity: 1-bit little-endian Valid signals as (byte, bit), others as raw extractors
    vbyte: list[int] = []
    vbit: list[int] = []
    vcols: list[int] = []
    vother: list[tuple[int, RawFn]] = []
    for j, m in enumerate(maps):
        vname = f"{m.signal}Valid"
        if not any(x.name == vname for x in msg.signals):
            continue
        vs = signal_spec(msg, vname)
        if vs.length == 1 and not vs.big_endian:
            vcols.append(j)
            vbyte.append(vs.start >> 3)
            vbit.append(vs.start & 7)
            continue
        vraw = compile_raw(MessageCodec(msg, [vname]).specs[0], msg.length)
        if vraw is None:
            return None
        vother.append((j, vraw))
    all_bits = vcols == list(range(len(maps)))
    vbyte_a = np.array(vbyte, dtype=np.intp)
    vbit_a = np.array(vbit, dtype=np.uint8)
    one_byte = len(set(vbyte)) == 1
    vcols_a = np.array(vcols, dtype=np.intp)

    def rows_fn(rows: np.ndarray) -> np.ndarray:
        m = rows.shape[0]
        if view_code is not None:
            raw = rows.view(view_code)[:, view_cols]
            v = raw * dbc_scale if any_dbc_scale else raw.astype(np.float64)
        else:
            v = np.empty((m, k))
            for j, f in enumerate(raws):
                v[:, j] = f(rows)
            if any_dbc_scale:
                v *= dbc_scale
        if any_dbc_off:
            v += dbc_off
        if not identity:
            v = v[:, index]
        if any_map_scale:
            v = v * map_scale
        if any_map_off:
            v = v + map_off
        if vcols:
            src = rows[:, vbyte[0]:vbyte[0] + 1] if one_byte else rows[:, vbyte_a]
            invalid = ((src >> vbit_a) & 1) == 0
            if all_bits:
                v[invalid] = math.nan
            else:
                sub = v[:, vcols_a]
                sub[invalid] = math.nan
                v[:, vcols_a] = sub
        for j, f in vother:
            v[f(rows) == 0, j] = math.nan   # a Valid raw value that is falsy (NaN is truthy)
        return v

    return rows_fn
