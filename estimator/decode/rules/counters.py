"""Alive counter continuity (stale, jump, lost frames) and the per-message period estimate
(``0.9 period + 0.1 interval`` over frames advancing by one) that tells a silence from a
jump; docs/can.md "End-to-end protection".
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from suspid.can.crc import COUNTER_MODULUS

_INF = math.inf
#: no silence while every interval stays below this x the smallest of the estimate and the
#: intervals so far (the estimate is a convex combination of them; margin for rounding)
SILENCE_SAFE = 1.5 * (1.0 - 1e-9)
#: rejection reasons, in check order
REJECT_REASONS: tuple[str, ...] = ("malformed", "frame_type", "time", "unknown_id", "dlc", "crc",
                                   "counter_stale", "counter_jump", "no_sync")
#: counter steps back (at most) that read as an old frame (``counter_stale``)
STALE_WINDOW = 5


@dataclass
class FrameCounts:
    """Frame counters of a decoder (``rejected``: reason -> frames)."""

    accepted: int = 0
    ignored: int = 0
    lost: int = 0
    rejected: dict[str, int] = field(default_factory=lambda: dict.fromkeys(REJECT_REASONS, 0))


class RouteState(Protocol):
    """What the counter and stale-tick rules keep per message."""

    last_c: int
    last_ts: float
    period: float
    last_arrival: float
    sync_n: int


class CounterRules:
    """The counter rules of one decoder, frame by frame (see the module docstring)."""

    __slots__ = ("counts", "rejected", "max_counter_delta", "stale_window")

    def __init__(self, counts: FrameCounts, max_counter_delta: int,
                 stale_window: int = STALE_WINDOW) -> None:
        self.counts = counts
        self.rejected = counts.rejected
        self.max_counter_delta = max_counter_delta
        self.stale_window = max(0, min(stale_window, COUNTER_MODULUS - 1 - max_counter_delta))

    def step(self, route: RouteState, c: int, t: float) -> bool:
        """Counter continuity of one frame at data time ``t`` (s); ``False``: rejected."""
        last = route.last_c
        if last >= 0 and (c - last) % COUNTER_MODULUS != 1:
            if not self.gap(route, c, last, t):
                return False
        elif last >= 0:
            el = t - route.last_ts
            per = route.period
            if per > 0 and el > 1.5 * per:
                steps = int(el / per + 0.5)
                if steps % COUNTER_MODULUS == 1:
                    self.counts.lost += steps - 1
            elif el > 0:
                route.period = el if per <= 0 else 0.9 * per + 0.1 * el
        route.last_c = c
        route.last_ts = t
        return True

    def gap(self, route: RouteState, c: int, last: int, ts: float) -> bool:
        """Counter did not advance by one: accept (lost frames) or reject; ``True`` = accept."""
        rejected = self.rejected
        if c == 15:
            rejected["counter_jump"] += 1
            return False
        delta = (c - last) % COUNTER_MODULUS
        # a gap whose length in periods matches the counter advance is counted from the time
        steps = int((ts - route.last_ts) / route.period + 0.5) if route.period > 0 else 0
        if 2 <= delta <= self.max_counter_delta:
            matched = steps > delta and (steps - delta) % COUNTER_MODULUS == 0
            self.counts.lost += (steps if matched else delta) - 1
            return True
        if steps >= 2 and (steps - delta) % COUNTER_MODULUS == 0:
            self.counts.lost += steps - 1
            return True
        if delta == 0 or delta >= COUNTER_MODULUS - self.stale_window:
            # old or repeated, unless a silence of a counter cycle: a restarted sender
            if not (route.period > 0 and ts - route.last_ts > COUNTER_MODULUS * route.period):
                rejected["counter_stale"] += 1
                return False
        route.last_c = c  # E2E profile 1: the sequence restarts from this frame
        route.last_ts = ts
        rejected["counter_jump"] += 1
        return False


def steady_frames(c: np.ndarray, t: np.ndarray, starts: np.ndarray, last_c: np.ndarray,
                  last_t: np.ndarray, period0: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Steady frames of consecutive message runs (counters ``c``, data times ``t`` in s, from
    ``starts``; each message's state before): those for which :meth:`CounterRules.step`
    reduces to :func:`period_after`. Returns the mask, each frame's interval (s) and run."""
    m = c.size
    rid = np.repeat(np.arange(starts.size), np.diff(np.append(starts, m)))
    prev_c = np.empty(m, dtype=np.int64)
    prev_c[1:] = c[:-1]
    prev_c[starts] = last_c
    prev_t = np.empty(m)
    prev_t[1:] = t[:-1]
    prev_t[starts] = last_t
    el = t - prev_t
    good = (c - prev_c) % COUNTER_MODULUS == 1
    fresh = starts[last_c < 0]          # first frame ever of its message
    e = el.copy()
    e[fresh] = _INF
    run_min = np.minimum.reduceat(e, starts)
    bound = np.minimum(run_min, np.where(period0 > 0, period0, _INF))
    good &= (e > 0) & (e <= SILENCE_SAFE * bound[rid])
    good[fresh] = True
    return good, el, rid


def period_after(jobs: list[tuple[float, int, int]], el: np.ndarray) -> list[float]:
    """Period estimates after the scalar recurrence over ``el[start:stop]``, bit for bit."""
    out = []
    for p, a, b in jobs:
        if a >= b:
            out.append(p)
            continue
        xs = el[a:b]
        if not p > 0:            # no estimate yet (or NaN): the first interval becomes it
            p = float(xs[0])
            xs = xs[1:]
        ys = 0.1 * xs
        if p > 0 and bool((ys > 0).all()):
            for y in ys.tolist():
                p = 0.9 * p + y
        else:
            for x in xs.tolist():
                p = 0.9 * p + 0.1 * x if p > 0 else x
        out.append(p)
    return out
