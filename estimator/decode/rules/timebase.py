"""Data time: which clock places a frame (:func:`choose_time_base`), the time order check
(:class:`TimeOrder`), frames' ticks from their alive counters (:func:`ticks_of_counters`), the
stale-tick rule (:func:`stale`) and the sensor clock across wraps and restarts
(:class:`TickClock`). docs/can.md "Sample time: SN_Sync".
"""
from __future__ import annotations

import math
import sys
from typing import Any

import numpy as np

from estimator.decode.rules.counters import RouteState
from suspid.can.crc import COUNTER_MODULUS

_INF = math.inf
#: consecutive 'time' rejections after which the time base is re-anchored (a clock reset)
TIME_RESYNC = 16
#: ``time_source="auto"``: frames of the DBC held while waiting for an ``SN_Sync``
AUTO_FRAMES = 64
#: silence (in periods, half the counter cycle) after which a data frame needs a new SN_Sync
STALE_PERIODS = COUNTER_MODULUS // 2


class TimeOrder:
    """The time order check: a time before ``last``, NaN or inf is rejected as ``time``; ``TIME_RESYNC`` in a
    row re-anchor the time base (``resyncs``)."""

    __slots__ = ("last", "rejects", "resyncs")

    def __init__(self) -> None:
        self.last = -sys.float_info.max
        self.rejects = 0
        self.resyncs = 0

    def admit(self, ts: np.ndarray) -> np.ndarray:
        """Which frames stamped ``ts`` (s, in arrival order) pass; ``last`` moves past them.

        A frame passes when finite and not before every earlier finite time (a frame it
        rejects never raised that maximum); the ``TIME_RESYNC``-th finite rejection in a row
        passes too, and the check starts again from it."""
        if ts.size and self.last <= ts[0] and ts[-1] < _INF and \
                (ts.size == 1 or bool((ts[1:] >= ts[:-1]).all())):
            self.last = float(ts[-1])   # in order and finite (NaN fails every compare)
            self.rejects = 0
            return np.ones(ts.size, dtype=bool)
        keep = np.zeros(ts.size, dtype=bool)
        pos = 0
        while pos < ts.size:
            t = ts[pos:]
            fin = np.isfinite(t)
            prior = np.maximum.accumulate(np.r_[self.last, np.where(fin, t, -_INF)[:-1]])
            ok = fin & (prior <= t)
            rej = fin & ~ok
            cr = np.cumsum(rej)
            since = np.maximum.accumulate(np.where(ok, cr, 0))
            run = np.where(np.logical_or.accumulate(ok), cr - since, self.rejects + cr)
            at = np.flatnonzero(rej & (run >= TIME_RESYNC))
            end = int(at[0]) if at.size else t.size
            keep[pos:pos + end] = ok[:end]
            passed = np.flatnonzero(ok[:end])
            if passed.size:
                self.last = float(t[passed[-1]])
            if not at.size:
                self.rejects = int(run[-1])
                break
            keep[pos + end] = True   # the clock was reset: re-anchor on this frame
            self.last = float(t[end])
            self.rejects = 0
            self.resyncs += 1
            pos += end + 1
        return keep


def ticks_of_counters(sync_tick: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The ticks nearest ``sync_tick`` whose residue mod 15 is the alive counter ``c`` (int64)."""
    d = (sync_tick - c) % COUNTER_MODULUS
    return sync_tick - d + np.where(d <= COUNTER_MODULUS // 2, 0, COUNTER_MODULUS)


def tick_times(ticks: np.ndarray, period: np.ndarray) -> np.ndarray:
    """Data times (s) of samples ``ticks`` at ``period`` s, rounded to the µs as SN_Sync's own."""
    return np.round(ticks * period * 1e6) / 1e6


def sync_times(ticks: np.ndarray, period_us: np.ndarray, arrival: np.ndarray) -> np.ndarray:
    """Data times (s) of SN_Sync frames, ``Tick x PeriodUs`` (the exact decimal time);
    ``arrival`` where PeriodUs is 0."""
    return np.where(period_us > 0, (ticks * period_us).astype(np.float64) / 1e6, arrival)


def stale(same_sync: Any, gap: Any, period: Any) -> Any:
    """The stale-tick rule, on scalars or arrays: no SN_Sync since the message's last frame
    (``same_sync``) and a silence ``gap`` (s) of more than ``STALE_PERIODS`` periods (s)."""
    return same_sync & (gap > STALE_PERIODS * period)


def stale_tick(route: RouteState, sync_n: int, period: float, arrival: float) -> bool:
    """Tick mode: whether a data frame arriving at ``arrival`` (s) is ``no_sync`` (a stale tick)."""
    return route.last_c >= 0 and bool(stale(route.sync_n == sync_n,
                                            arrival - route.last_arrival,
                                            max(route.period, period)))


def fresh_ticks(sn: np.ndarray, prev_sn: np.ndarray, arrival: np.ndarray,
                prev_arrival: np.ndarray, period: np.ndarray, known: np.ndarray) -> np.ndarray:
    """Data frames whose tick is certainly usable: :func:`stale` with the SN_Sync period
    alone (never above :func:`stale_tick`'s), a known tick and period."""
    return known & ~np.isnan(period) & ~stale(sn == prev_sn, arrival - prev_arrival, period)


class SyncTrack:
    """SN_Sync state along a batch segment (tick mode): what every frame position sees."""

    def __init__(self, tick0: int | None, n0: int, period0: float | None,
                 shift0: int = 0) -> None:
        self.tick0 = tick0
        self.n0 = n0
        self.period0 = period0
        self.shift0 = shift0
        self.pos = np.empty(0, dtype=np.int64)
        self.ticks = np.empty(0, dtype=np.int64)
        self.periods = np.empty(0)
        self.shifts = np.empty(0, dtype=np.int64)
        #: counter shifts of the SN_Sync run being accepted
        self.pending_shifts: np.ndarray | None = None
        # the other messages' frames from index lo on: SN_Sync count, tick known, period
        self.lo = 0
        self.sn = np.empty(0, dtype=np.int64)
        self.known = np.empty(0, dtype=bool)
        self.per = np.empty(0)

    def add(self, pos: np.ndarray, ticks: np.ndarray, period_us: np.ndarray,
            shifts: np.ndarray | None = None) -> None:
        """The accepted SN_Sync frames of the segment: positions, ticks, periods (µs), shifts."""
        self.shifts = np.zeros(len(pos), dtype=np.int64) if shifts is None else \
            np.asarray(shifts, dtype=np.int64)
        given = period_us > 0
        last = np.maximum.accumulate(np.where(given, np.arange(given.size), -1))
        per = period_us * 1e-6
        self.pos = np.asarray(pos, dtype=np.int64)
        self.ticks = np.asarray(ticks, dtype=np.int64)
        self.periods = np.where(last >= 0, per[np.maximum(last, 0)],
                                math.nan if self.period0 is None else self.period0)

    def at(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                         np.ndarray]:
        """At positions ``q``: SN_Sync count, tick, tick known, period (NaN unknown), shift."""
        k = np.searchsorted(self.pos, q)   # 0: the state before the segment
        st = np.append(np.int64(0 if self.tick0 is None else self.tick0), self.ticks)[k]
        per = np.append(math.nan if self.period0 is None else self.period0, self.periods)[k]
        sh = np.append(np.int64(self.shift0), self.shifts)[k]
        return self.n0 + k, st, (k > 0) | (self.tick0 is not None), per, sh


#: SN_Sync's Tick is a 32-bit counter
TICK_MODULUS = 1 << 32
#: a restart: the Tick falls back by more than this (s) and lies within it (plus the
#: silence) of 0
RESTART_S = 1.0


class TickClock:
    """The node's tick as one unbroken count, SN_Sync's raw ``Tick`` plus ``base``, across
    32-bit ``wraps`` and node ``restarts`` (a Tick that falls back within ``RESTART_S`` of
    the silence between two SN_Sync frames; anything else is a late SN_Sync)."""

    __slots__ = ("base", "last_raw", "last_arrival", "wraps", "restarts")

    def __init__(self) -> None:
        self.base = 0
        self.last_raw: int | None = None
        self.last_arrival = 0.0
        self.wraps = 0
        self.restarts = 0

    def extend(self, raw: int, period_us: float, arrival: float) -> int:
        """The unbroken tick of an SN_Sync (raw ``Tick``, ``PeriodUs``, arrival time in s)."""
        last = self.last_raw
        if last is not None and raw < last:
            period = period_us * 1e-6
            if not period > 0:
                return raw + self.base
            silence = max(arrival - self.last_arrival, 0.0) if math.isfinite(arrival) else 0.0
            if ((raw - last) % TICK_MODULUS) * period <= silence + RESTART_S:
                self.base += TICK_MODULUS
                self.wraps += 1
            elif (last - raw) * period > RESTART_S and raw * period <= silence + RESTART_S:
                self.base = last + self.base + max(1, round(silence / period)) - raw
                self.restarts += 1
            else:
                return raw + self.base
        self.last_raw = raw
        self.last_arrival = arrival
        return raw + self.base

    def extend_many(self, raw: Any, period_us: Any, arrival: np.ndarray) -> np.ndarray:
        """:meth:`extend` of SN_Sync frames in order (int64 array)."""
        tk = np.asarray(raw, dtype=np.int64)
        if not tk.size:
            return tk
        last = tk[0] if self.last_raw is None else self.last_raw
        if tk[0] >= last and (tk.size < 2 or bool((tk[1:] >= tk[:-1]).all())):
            self.last_raw = int(tk[-1])
            self.last_arrival = float(arrival[-1])
            return tk + self.base
        pus = np.broadcast_to(np.asarray(period_us, dtype=np.float64), tk.shape)
        return np.array([self.extend(int(t), float(u), float(a))
                         for t, u, a in zip(tk.tolist(), pus.tolist(), arrival.tolist())],
                        dtype=np.int64)


def choose_time_base(ids: np.ndarray, sync_ids: np.ndarray, known_ids: np.ndarray,
                     final: bool) -> str | None:
    """``"auto"``: ``"tick"``, ``"timestamp"`` or None (undecided) from the first frames."""
    if np.isin(ids, sync_ids).any():
        return "tick"
    if final or int(np.isin(ids, known_ids).sum()) >= AUTO_FRAMES:
        return "timestamp"
    return None


def first_sync(ids: np.ndarray, sync_ids: np.ndarray) -> int:
    """Index of the first SN_Sync among the first ``AUTO_FRAMES`` frames ``ids`` (-1: none)."""
    hit = np.flatnonzero(np.isin(ids[:AUTO_FRAMES], sync_ids))
    return int(hit[0]) if hit.size else -1
