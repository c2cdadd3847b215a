"""The decoder's rules frame by frame, as docs/can.md states them: the oracle of the engine.

:class:`FrameByFrame` is a :class:`~estimator.decode.engine.DecodeEngine` whose ``process``
takes one frame at a time through scalar forms of every rule (time order, ID, DLC, CRC,
alive counter, SN_Sync tick and stale tick, decode, store). The engine itself has one path,
whole batches through arrays; the tests feed the same frames to both and compare everything.
"""
from __future__ import annotations

import math
import sys
from typing import Sequence

import numpy as np

from estimator.decode.buffer import Source
from estimator.decode.engine import DecodeEngine
from estimator.decode.listener import DecodeListener
from estimator.decode.routes import DATA, EXT, SYNC, Route
from estimator.decode.rules.e2e import Payload
from estimator.decode.rules.timebase import TIME_RESYNC, stale_tick
from suspid.can.crc import COUNTER_MODULUS, e2e_crc
from suspid.can.logs import FrameArrays

_INF = math.inf


class ScalarTimeOrder:
    """The time order check of one frame at a time (``TimeOrder`` without arrays)."""

    def __init__(self) -> None:
        self.last = -sys.float_info.max
        self.rejects = 0
        self.resyncs = 0

    def admit_one(self, ts: float) -> bool:
        if not self.last <= ts < _INF:  # backwards, NaN or inf
            if not -_INF < ts < _INF:
                return False   # NaN/inf: never a data time, never a re-anchor
            self.rejects += 1
            if self.rejects < TIME_RESYNC:
                return False
            self.resyncs += 1
        self.rejects = 0
        self.last = ts
        return True


def tick_of_counter(sync_tick: int, c: int) -> int:
    """The tick nearest ``sync_tick`` whose residue mod 15 is the alive counter ``c``."""
    d = (sync_tick - c) % COUNTER_MODULUS
    return sync_tick - d if d <= COUNTER_MODULUS // 2 else sync_tick - d + COUNTER_MODULUS


def tick_time(tick: int, period: float) -> float:
    """Data time (s) of sample ``tick`` at ``period`` s, rounded to the µs."""
    return round(tick * period * 1e6) / 1e6


def push_one(src: Source, t: float, values: Sequence[float]) -> None:
    """One row into a message's ring: a full fixed ring overwrites its oldest row, a
    growable one doubles when the write index reaches its end."""
    with src._lock:
        i = src.w
        if src.n == src.cap:
            src.overwritten += 1
        else:
            src.n += 1
        src.t[i] = t
        for col, v in zip(src.cols, values):
            col[i] = v
        i += 1
        if i == src.cap:
            if src.growable:
                src._grow(2 * src.cap)
                i = src.cap // 2
            else:
                i = 0
        src.w = i


def _one_row(data: Payload) -> np.ndarray:
    return np.frombuffer(bytes(data).ljust(max(8, len(data)), b"\0"),
                         dtype=np.uint8).reshape(1, -1)


class FrameByFrame(DecodeEngine):
    """Every frame through the rules one by one (see the module docstring)."""

    def __init__(self, *args: object, **kw: object) -> None:
        super().__init__(*args, **kw)  # type: ignore[arg-type]
        self.order = ScalarTimeOrder()  # type: ignore[assignment]

    def process(self, fa: FrameArrays, lo: int, hi: int) -> None:
        for i in range(lo, hi):
            self.frames += 1
            if fa.frame_type[i]:
                self._rejected["frame_type"] += 1
                continue
            fid = int(fa.arbitration_id[i])
            self.validate(float(fa.timestamp[i]), fid | EXT if fa.is_extended[i] else fid,
                          fa.payload(i))

    def validate(self, ts: float, key: int, data: Payload) -> None:
        rejected = self._rejected
        if not self.order.admit_one(ts):  # type: ignore[attr-defined]
            rejected["time"] += 1
            return
        route = self.routes.by_key.get(key)
        if route is None:
            if key in self.routes.known:
                self.counts.ignored += 1
            else:
                rejected["unknown_id"] += 1
            return
        if len(data) != route.dlc:
            rejected["dlc"] += 1
            return
        c = -1
        ext = ext_shift = 0
        if route.e2e:
            if e2e_crc(key & ~EXT, data) != data[0]:
                rejected["crc"] += 1
                return
            c = data[1] & 0x0F
            arrival = ts
            if self.tick_time:
                if route.kind == SYNC:
                    tick, period_us = route.decode(data)
                    ext = self.clock.extend(int(tick), period_us, arrival)
                    ext_shift = (ext - int(tick)) % COUNTER_MODULUS
                    if period_us > 0:
                        ts = ext * period_us / 1e6
                elif route.kind == DATA and self.sync_tick is not None and self.period:
                    if stale_tick(route, self.sync_n, self.period, arrival):
                        rejected["no_sync"] += 1
                        return
                    ts = tick_time(tick_of_counter(
                        self.sync_tick, (c + self.sync_shift) % COUNTER_MODULUS), self.period)
                elif route.kind != DATA and self.sync_tick is not None and self.period:
                    ts = tick_time(self.sync_tick, self.period)   # sent in the last SN_Sync's tick
                route.last_arrival = arrival
                route.sync_n = self.sync_n
            if not self.counters.step(route, c, ts):
                return
        if route.kind == DATA:
            if self.tick_time and (self.sync_tick is None or c < 0):
                rejected["no_sync"] += 1
                return
            self._store(route, ts, data)
        elif route.kind == SYNC:
            tick, period_us = route.decode(data)
            self.sync_tick = ext if self.tick_time and route.e2e else int(tick)
            self.sync_shift = ext_shift if self.tick_time and route.e2e else self.sync_shift
            self.sync_n += 1
            if period_us > 0:
                self.period = period_us * 1e-6
        elif not self._special(route, data, ts):
            return
        route.accepted += 1
        self.counts.accepted += 1

    @staticmethod
    def _store(route: Route, ts: float, data: Payload) -> None:
        if route.pages is not None:
            route.pages.push_many(np.array([ts]), _one_row(data))
        elif route.source is not None and route.row is not None:
            push_one(route.source, ts, route.row(data))


def frame_by_frame(lst: DecodeListener) -> DecodeListener:
    """``lst`` with its engine replaced by :class:`FrameByFrame` (before any frame)."""
    eng = lst.engine
    lst.engine = FrameByFrame(eng.db, eng.routes, tick_time=eng.tick_time,
                              max_counter_delta=eng.counters.max_counter_delta,
                              collect_alerts=eng.collect_alerts)
    return lst
