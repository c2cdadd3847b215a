"""Feeding logged frames to listeners: as arrays (:func:`feed_log`), in a direct loop
(:func:`feed`), or through ``can.Notifier`` (:class:`ReplayBus`; same results, slower)."""
from __future__ import annotations

import itertools
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Optional

import can
import numpy as np

from estimator.decode.listener import DecodeListener
from suspid.can.logs import FrameArrays, ReadStats, read_log, read_log_arrays


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
    return _reorder(fa, np.argsort(fa.timestamp, kind="stable"))


def _reorder(fa: FrameArrays, order: np.ndarray) -> FrameArrays:
    """The frames of ``fa`` in the order of the row indices ``order``."""
    out = FrameArrays(fa.timestamp[order], fa.arbitration_id[order], fa.is_extended[order],
                      fa.frame_type[order], fa.length[order], fa.data[order])
    if fa.long_data:
        where = np.empty(order.size, dtype=np.int64)
        where[order] = np.arange(order.size)
        out.long_data = {int(where[i]): v for i, v in fa.long_data.items()}
    return out


def feed(listener: can.Listener, messages: Iterable[can.Message]) -> int:
    """Call ``listener.on_message_received`` for every message; return how many."""
    on = listener.on_message_received
    n = 0
    for msg in messages:
        on(msg)
        n += 1
    return n


def feed_log(listener: can.Listener, path: str | Path, stats: Optional[ReadStats] = None, *,
             poll: Optional[Callable[[], int]] = None, channel: Optional[str] = None) -> int:
    """Feed every frame of a CAN log (``.log``, ``.asc``, ``.blf``, ``.trc``, ``.mf4``) to a
    listener as fast as possible (a ``DecodeListener`` gets arrays; same results); returns the
    frames fed. ``stats`` counts what was read; ``poll()`` is called after the first frame,
    then after as many frames as it returns; ``channel``: one bus channel of a multi-bus log."""
    left = 1
    n = 0
    if not isinstance(listener, DecodeListener):
        on = listener.on_message_received
        for msg in read_log(path, stats, channel=channel):
            on(msg)
            n += 1
            if poll is not None:
                left -= 1
                if left <= 0:
                    left = max(1, int(poll()))
    else:
        first = listener.time_source_requested == "auto"
        for fa in _placed(listener, path, stats, channel):
            size = len(fa)
            if first:   # "auto": decided on the first chunk (_placed)
                first = False
                k = listener.sync_first_index(fa.arbitration_id)
                if k > 0:
                    fa = sync_to_front(fa, k)
            if poll is None:
                n += listener.feed_arrays(fa)
                continue
            pos = 0
            while pos < size:
                take = min(left, size - pos)
                listener.feed_arrays(fa, pos, pos + take)
                pos += take
                n += take
                left -= take
                if left <= 0:
                    left = max(1, int(poll()))
    finish = getattr(listener, "finish", None)
    if finish is not None:
        finish()
    return n


def _placed(listener: DecodeListener, path: str | Path, stats: Optional[ReadStats],
            channel: Optional[str] = None) -> Iterator[FrameArrays]:
    """The chunks of a log (with arrival slots: read twice, the times then the frames)."""
    chunks = read_log_arrays(path, stats, channel=channel)
    first = next(chunks, None)
    if first is None:
        return
    listener.choose_time_base(first.arbitration_id, final=True)
    if not listener.places_arrivals():
        yield first
        yield from chunks
        return
    # pass 1: each data message's arrival times; are they finite and in order?
    per: dict[int, list[np.ndarray]] = {k: [] for k in listener.data_keys()}
    ordered = True
    last = -np.inf
    for fa in itertools.chain((first,), chunks):
        ts = fa.timestamp
        if ordered and ts.size:
            ordered = bool(np.isfinite(ts).all()) and ts[0] >= last and \
                not bool((np.diff(ts) < 0).any())
            last = ts[-1]
        keys = fa.arbitration_id | (fa.is_extended.astype(np.int64) << 31)
        good = ~fa.frame_type
        for k, got in per.items():
            got.append(ts[(keys == k) & good])
    del first, fa, ts, keys, good   # the loop ran at least once (over `first`)
    moved = listener.message_slot_times({k: np.concatenate(v) for k, v in per.items()}) \
        if ordered else {}
    del per
    # pass 2: the frames (read and counted once already)
    again = read_log_arrays(path, ReadStats(), channel=channel)
    if not moved:
        yield from again
        return
    whole = concat_frames(list(again))
    keys = whole.arbitration_id | (whole.is_extended.astype(np.int64) << 31)
    good = ~whole.frame_type
    times = whole.timestamp.copy()
    for k, tm in moved.items():
        times[(keys == k) & good] = tm
    whole.timestamp = times
    yield sort_frames(whole)


def sync_to_front(fa: FrameArrays, k: int) -> FrameArrays:
    """``fa`` with row ``k`` moved to the front, with the first row's timestamp."""
    out = _reorder(fa, np.r_[k, np.arange(k), np.arange(k + 1, len(fa))])
    out.timestamp[0] = fa.timestamp[0]   # a copy: fancy indexing
    return out


class ReplayBus(can.BusABC):
    """A read-only python-can bus that yields the frames of an iterable (e.g. a log)."""

    def __init__(self, messages: Iterable[can.Message], channel: str = "replay",
                 **kwargs: Any) -> None:
        self._it: Iterator[can.Message] = iter(messages)
        self.exhausted = False
        self.channel_info = f"replay of {channel}"
        super().__init__(channel=channel, **kwargs)

    def _recv_internal(self, timeout: Optional[float]) -> tuple[Optional[can.Message], bool]:
        if self.exhausted:
            if timeout:
                time.sleep(min(timeout, 0.01))
            return None, False
        try:
            return next(self._it), False
        except StopIteration:
            self.exhausted = True
            return None, False

    def send(self, msg: can.Message, timeout: Optional[float] = None) -> None:
        raise can.CanOperationError("ReplayBus is read-only")


def feed_with_notifier(listener: can.Listener, messages: Iterable[can.Message],
                       poll: float = 0.05) -> None:
    """Run ``messages`` through ``can.Notifier`` into ``listener`` and wait until done."""
    bus = ReplayBus(messages)
    notifier = can.Notifier(bus, [listener], timeout=poll)
    try:
        while not bus.exhausted:
            time.sleep(poll)
        time.sleep(2 * poll)  # let the notifier thread deliver the last frame
    finally:
        notifier.stop()
        bus.shutdown()
