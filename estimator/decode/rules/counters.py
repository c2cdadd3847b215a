"""Alive counter continuity and the per-message period estimate.

Per message the decoder keeps the last counter ``last_c`` (-1: no frame yet), the data time
of the last frame ``last_ts`` (s) and a period estimate ``period`` (s, 0: none yet; an
exponential average ``0.9 period + 0.1 interval`` of the intervals between frames whose
counters advance by one).

* The next counter value (advance 1 mod 15) is accepted. After a silence of more than 1.5
  periods an advance of 1 means 15, 30, ... frames were lost that a 4-bit counter cannot
  show; the time shows them and they are counted in ``lost``.
* An advance of 2..``max_counter_delta`` is accepted and its missing frames counted lost
  (more, when the time since the last frame says a whole counter cycle more went missing).
* A repeated or older counter (up to ``stale_window`` steps back) is ``counter_stale``,
  unless the message was silent for more than a counter cycle (a restarted sender).
* Anything else, and the invalid value 15, is ``counter_jump``: the frame re-synchronises
  the sequence (AUTOSAR E2E profile 1) but is not accepted.

Scalar: :class:`CounterRules` (one frame). Arrays: :func:`steady_frames` (which frames of a
run of messages need only the period recurrence) and :func:`period_after` (that recurrence,
bit for bit the scalar one).
"""
from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from estimator.decode.stats import FrameCounts
from suspid.can.crc import COUNTER_MODULUS

_INF = math.inf
#: the period estimate cannot trigger the silence rule while every interval stays below
#: 1.5 x (1 - 1e-9) x the smallest of the estimate and the intervals so far (the estimate
#: is a convex combination of them; the margin covers its rounding over 1e5+ updates)
SILENCE_SAFE = 1.5 * (1.0 - 1e-9)


class CounterState(Protocol):
    """What the counter rules keep per message (see the module docstring)."""

    last_c: int
    last_ts: float
    period: float


class CounterRules:
    """The counter rules of one decoder (frame by frame: the reference).

    Parameters
    ----------
    counts : FrameCounts
        Where lost frames and ``counter_stale``/``counter_jump`` rejections are counted.
    max_counter_delta : int
        Largest accepted counter advance (1 = no frame may be lost).
    stale_window : int
        Counter steps back still read as an old (late or duplicate) frame.
    """

    __slots__ = ("counts", "rejected", "max_counter_delta", "stale_window")

    def __init__(self, counts: FrameCounts, max_counter_delta: int, stale_window: int) -> None:
        self.counts = counts
        self.rejected = counts.rejected
        self.max_counter_delta = max_counter_delta
        self.stale_window = stale_window

    def step(self, route: CounterState, c: int, t: float) -> bool:
        """Counter continuity of one frame at data time ``t`` (s); ``False``: rejected.

        The next counter value is accepted and updates the period estimate; a silence
        whose length in periods is 1 mod 15 counts the frames the counter cannot show as
        lost. Any other value goes to :meth:`gap`.
        """
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

    def gap(self, route: CounterState, c: int, last: int, ts: float) -> bool:
        """Counter did not advance by one: accept (lost frames) or reject; ``True`` = accept."""
        rejected = self.rejected
        if c == 15:
            rejected["counter_jump"] += 1
            return False
        delta = (c - last) % COUNTER_MODULUS
        # a 4-bit counter cannot tell 11 lost frames from a frame 4 steps old, nor 2 lost
        # frames from 17; the time since the last frame of this ID can: a gap whose length
        # in periods matches the counter advance is counted from the time
        steps = int((ts - route.last_ts) / route.period + 0.5) if route.period > 0 else 0
        if 2 <= delta <= self.max_counter_delta:
            matched = steps > delta and (steps - delta) % COUNTER_MODULUS == 0
            self.counts.lost += (steps if matched else delta) - 1
            return True
        if steps >= 2 and (steps - delta) % COUNTER_MODULUS == 0:
            self.counts.lost += steps - 1
            return True
        if delta == 0 or delta >= COUNTER_MODULUS - self.stale_window:
            # an old or repeated frame arrives close to the newest one; after a silence of
            # more than a counter cycle it is a restarted sender (node reboot): re-sync
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
    """Frames of consecutive message runs that only update the period estimate.

    A frame is *steady* when its counter advances by exactly one, and its interval is
    positive and short enough that no period estimate reachable from the run's start can
    call it a silence (below :data:`SILENCE_SAFE` x the smallest of the run's intervals and
    its period before); the first frame ever of a message always is. For the frames of a
    run up to its first unsteady one, :meth:`CounterRules.step` reduces to
    :func:`period_after`.

    Parameters
    ----------
    c : ndarray of int64, shape (m,)
        Counters, the runs one after the other.
    t : ndarray of float64, shape (m,)
        Data times (s).
    starts : ndarray of int64, shape (runs,)
        Index of each run's first frame.
    last_c, last_t, period0 : ndarray, shape (runs,)
        Each message's counter (-1: none yet), data time and period before its run.

    Returns
    -------
    steady : ndarray of bool, shape (m,)
    el : ndarray of float64, shape (m,)
        Interval of each frame since the message's previous one (s).
    rid : ndarray of int64, shape (m,)
        Run of each frame.
    """
    m = c.size
    rid = np.repeat(np.arange(starts.size), np.diff(np.r_[starts, m]))
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
    """Period estimates after the recurrence over ``el[start:stop]`` for every job.

    ``jobs``: ``(period before, start, stop)``; the recurrence is the scalar rule's
    ``period = el if period <= 0 else 0.9 * period + 0.1 * el``. A Python loop: the result
    must be bit for bit the scalar one, and no array operation rounds the same way step by
    step (``scipy.signal.lfilter`` would, but importing ``scipy.signal`` costs ~1 s per
    process start).

    The loop is the scalar one with two steps taken out of it, which changes no rounding:
    the products ``0.1 * el`` are computed as one array operation (one IEEE multiplication
    each, the same double), and the test ``period > 0`` is made once: when every product
    is positive, a positive period stays positive (``0.9 * p`` is >= 0 and adding a
    positive double to it rounds to at least that double), so the test would always pass.
    A job with a non-positive (or NaN) product runs the scalar loop as it is.
    """
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
