"""Whole batches of frames (:class:`~suspid.can.logs.FrameArrays`): joined, sorted by time."""
from __future__ import annotations

import numpy as np

from suspid.can.logs import FrameArrays


def concat_frames(parts: list[FrameArrays]) -> FrameArrays:
    """Frame batches joined into one (row indices of ``long_data`` shifted)."""
    if len(parts) == 1:
        return parts[0]
    out = FrameArrays(np.concatenate([p.timestamp for p in parts]),
                      np.concatenate([p.arbitration_id for p in parts]),
                      np.concatenate([p.is_extended for p in parts]),
                      np.concatenate([p.frame_type for p in parts]),
                      np.concatenate([p.length for p in parts]),
                      np.concatenate([p.data for p in parts]))
    base = 0
    for p in parts:
        for i, v in p.long_data.items():
            out.long_data[base + i] = v
        base += len(p)
    return out


def sort_frames(fa: FrameArrays) -> FrameArrays:
    """``fa`` in time order (stable: frames of equal time keep their order)."""
    order = np.argsort(fa.timestamp, kind="stable")
    out = FrameArrays(fa.timestamp[order], fa.arbitration_id[order], fa.is_extended[order],
                      fa.frame_type[order], fa.length[order], fa.data[order])
    if fa.long_data:
        where = np.empty(order.size, dtype=np.int64)
        where[order] = np.arange(order.size)
        out.long_data = {int(where[i]): v for i, v in fa.long_data.items()}
    return out
