"""Sample slots from arrival times: the time base of a stream that carries no sensor clock.

A foreign stream (no ``SN_Sync`` tick, often no counters) has only the frames' arrival
timestamps. They are not the times the samples were taken: a USB adapter or a busy bus adds
jitter, delivers several sample periods at once (bursts) and delays frames. What arrival
times do tell, for the frames of one message:

* the frames arrive in the order they were sent, one per sample period ``P``;
* a frame arrives no earlier than its sample was taken (arrival is an upper bound);
* a gap (frames missing) delays every later frame for good, by whole periods; a delivery
  delay or a burst delays a few frames, and later frames arrive early again.

So each frame ``i`` of a message is given the slot ``k_i = i + (frames missing before
it)``, and the data time ``a + k_i P``:

1. ``P`` is first estimated from the lower convex hull of the points ``(i, t_i)``
   (:func:`hull_period`): sample times lie on a line below every arrival; the hull runs
   through the least delayed frames (the last of each burst, the undelayed ones) with the
   slope ``P``, and bends only where a gap lifts the later frames; the slope of the hull
   edge under the median frame is taken;
2. gaps are where the lower envelope of ``u_i = t_i - i P`` rises: at each frame the
   least ``u`` of the ``DETECT`` frames from it on minus the least of the ``DETECT``
   frames before it. A delay or a burst raises a few frames' ``u``, which the other frames of
   the window hide; jitter moves both minima alike; a gap raises every later ``u`` by
   whole periods, which nothing hides. Where the rise exceeds half a period, the frames
   missing are the least ``u`` of up to ``SIDE`` frames after that stretch above the
   least of up to ``SIDE`` frames before it, in whole periods. Frames inside the stretch
   may be read as before or after the gap (arrival times cannot tell); the gap's size is
   right. In the last ``TAIL`` frames a gap cannot be told from a delay: they are counted
   consecutive;
3. ``P`` is refitted by least squares of ``t`` on the slots (delays that do not drift do
   not bias the slope), and steps 2-3 are repeated; the last fit is rounded to whole
   microseconds when that lies within ``SNAP_SE`` standard errors (timers count µs);
4. the anchor ``a`` is the lower envelope ``min(t_i - k_i P)``: the earliest the samples
   can have been taken.

A message whose arrival times already lie on their slot grid (within ``REGULAR_TOL`` of a
period: an encoded CSV, a node's log) keeps them, and so does one more than ``STAMPED`` of
whose intervals are exactly one period: a clock that ticks with the samples stamped them
(a logger's schedule, the sender's own clock), so they carry no transport jitter and the
odd intervals are the source's own. Messages whose periods agree within
``SAME_RATE`` share one period and the phase of the first of them
(:func:`place_messages`), so the frames of one sample land on one grid cell.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

#: the last frames of a message, in which a gap cannot be told from a delivery delay
TAIL = 32
#: frames whose least arrival delay gives the lower envelope on each side of a frame, to
#: find where it rises (short: two gaps close together stay apart) ...
DETECT = 32
#: ... and to measure by how much (long: the least delay of a few frames varies)
SIDE = 128
#: fewest frames of a message whose arrival times are placed in slots
MIN_FRAMES = 8
#: arrival times within this fraction of a period of their slot grid are kept as they are
REGULAR_TOL = 1e-4
#: a message more than this fraction of whose arrival intervals are exactly its median
#: positive interval was stamped by a clock that ticks with its samples: kept as it is
STAMPED = 0.5
#: messages whose periods differ by less than this (relative) share one period and phase
SAME_RATE = 1e-3
#: a period is rounded to whole µs when that is within this many standard errors
SNAP_SE = 3.0
#: least-squares refits of the period
REFITS = 3


@dataclass
class Slots:
    """The sample slots of one message's frames.

    Attributes
    ----------
    k : ndarray of int64, shape (n,)
        Slot of each frame (0 for the first; a gap of ``g`` frames adds ``g``).
    period : float
        Sample period (s).
    anchor : float
        Data time (s) of slot 0: the lower envelope of ``t - k P``.
    missing : int
        Frames missing (the gaps' total).
    regular : bool
        The arrival times are kept: they lie on the slot grid, or a clock that ticks with
        the samples stamped them.
    t : ndarray of float64, shape (n,)
        The arrival times (s).
    """

    k: np.ndarray
    period: float
    anchor: float
    missing: int
    regular: bool
    t: np.ndarray

    def envelope(self, period: float) -> float:
        """Lower envelope ``min(t - k period)`` (s): the anchor for another period."""
        return float(np.min(self.t - self.k * period))

    def times(self) -> np.ndarray:
        """Data time (s) of every frame: ``anchor + k period``."""
        return self.anchor + self.k * self.period


def _window_min(u: np.ndarray, w: int) -> tuple[np.ndarray, np.ndarray]:
    """``(ahead, behind)``: at each ``i`` the least of ``u[i:i+w]`` and of ``u[i-w:i]`` (the
    windows cut at the ends; ``behind[0]`` is ``u[0]``)."""
    n = u.size
    pad = np.full(w - 1, np.inf)
    ahead = sliding_window_view(np.r_[u, pad], w).min(axis=1)
    behind = np.empty(n)
    behind[0] = u[0]
    behind[1:] = sliding_window_view(np.r_[pad, u], w).min(axis=1)[:n - 1]
    return ahead, behind


def _slots(t: np.ndarray, period: float) -> np.ndarray:
    """Slots of arrival times ``t`` for a period estimate (step 2 of the module docstring)."""
    n = t.size
    u = t - np.arange(n) * period
    side = min(SIDE, n)
    ahead, behind = _window_min(u, min(DETECT, n))
    rise = ahead - behind
    rise[0] = 0.0
    rise[max(1, n - TAIL):] = 0.0         # the last frames: a delay, not a gap
    k = np.arange(n, dtype=np.int64)
    up = rise > 0.5 * period
    if not up.any():
        return k
    edge = np.diff(np.r_[False, up, False].astype(np.int8))
    starts = np.flatnonzero(edge == 1).tolist()
    ends = np.flatnonzero(edge == -1).tolist()
    # each stretch where the envelope rises: the least u of up to SIDE frames after it
    # (before the next stretch) above the least of up to SIDE frames before it (after the
    # previous one), in whole periods
    for q, (a, b) in enumerate(zip(starts, ends)):
        lo = ends[q - 1] if q else 0
        hi = starts[q + 1] if q + 1 < len(starts) else n
        before = float(u[max(lo, a - side):a].min())
        after = float(u[b:min(hi, b + side)].min())
        g = int(np.rint((after - before) / period))
        if g > 0:
            # the gap lies after the last frame of the stretch that arrived too early to
            # be after it (a sample is never taken after its frame arrives)
            early = np.flatnonzero(u[a:b] < before + (g - 0.5) * period)
            k[a + (int(early[-1]) + 1 if early.size else 0):] += g
    return k


def hull_period(t: np.ndarray) -> float:
    """Slope (s per frame) of the lower convex hull of ``(i, t_i)`` under the middle frame.

    The hull's edges are the straight runs of the lower envelope; bursts and delays lie
    above it, a gap makes it bend (a steeper edge across the gap): the edge the middle
    frame lies under belongs to the longest stretch without a gap, or is the slope of a
    stretch that holds half the frames.
    """
    n = t.size
    hull: list[int] = []
    tl = t.tolist()
    for i in range(n):
        while len(hull) >= 2:
            a, b = hull[-2], hull[-1]
            # keep b only if it lies strictly below the chord a -> i
            if (tl[b] - tl[a]) * (i - a) >= (tl[i] - tl[a]) * (b - a):
                hull.pop()
            else:
                break
        hull.append(i)
    if len(hull) < 2:
        return 0.0
    idx = np.array(hull)
    slopes = np.diff(t[idx]) / np.diff(idx)
    span = np.diff(idx).astype(np.float64)
    order = np.argsort(slopes, kind="stable")
    cum = np.cumsum(span[order])
    return float(slopes[order][int(np.searchsorted(cum, 0.5 * cum[-1]))])


def _fit_period(t: np.ndarray, k: np.ndarray) -> float:
    """Least-squares slope (s per slot) of ``t`` on ``k``."""
    kc = k - k.mean()
    den = float(np.dot(kc, kc))
    return float(np.dot(kc, t - t.mean())) / den if den > 0 else 0.0


def arrival_slots(t: np.ndarray) -> Slots | None:
    """Sample slots of one message's arrival times (see the module docstring).

    Parameters
    ----------
    t : ndarray of float64, shape (n,)
        Arrival times (s) of the message's frames, in arrival order.

    Returns
    -------
    Slots or None
        None when the times cannot be placed: fewer than ``MIN_FRAMES`` frames, a time
        that is not finite or goes back (a clock reset: left to the decoder's time check),
        or no positive period.
    """
    n = t.size
    if n < MIN_FRAMES or not bool(np.isfinite(t).all()) or bool((np.diff(t) < 0).any()):
        return None
    regular = _regular(t)
    if regular is not None:
        return regular
    d = np.diff(t)
    pos = d[d > 0]
    if pos.size:
        med = float(np.median(pos))
        if float(np.mean(np.abs(d - med) <= REGULAR_TOL * med)) > STAMPED:
            # most intervals are exactly one period: a clock that ticks with the samples
            # stamped them (no transport jitter); the odd intervals are the source's own
            return Slots(np.arange(n, dtype=np.int64), med, float(t[0]), 0, True, t)
    p = hull_period(t)
    if not p > 0:
        return None
    k = _slots(t, p)
    for _ in range(REFITS):
        p_new = _fit_period(t, k)
        if not p_new > 0:
            return None
        p = p_new
        k = _slots(t, p)
    p = _snap(t, k, _fit_period(t, k))
    if not p > 0:
        return None
    r = t - k * p
    return Slots(k, p, float(r.min()), int(k[-1] - (n - 1)), False, t)


def _snap(t: np.ndarray, k: np.ndarray, p: float) -> float:
    """``p`` rounded to whole microseconds when that lies within ``SNAP_SE`` standard errors
    of the least-squares slope (timers count whole µs; the data cannot tell the difference,
    and a slot grid then ends where the sender's does)."""
    p_us = round(p * 1e6) / 1e6
    kc = k - k.mean()
    den = float(np.dot(kc, kc))
    if not den > 0 or not p_us > 0:
        return p
    resid = t - t.mean() - p * kc
    se = float(np.sqrt(np.dot(resid, resid) / max(1, t.size - 2) / den))
    return p_us if abs(p_us - p) <= SNAP_SE * se else p


def _regular(t: np.ndarray) -> Slots | None:
    """The slots of arrival times that already lie on a uniform grid (within
    ``REGULAR_TOL`` of its step, gaps allowed), else None."""
    d = np.diff(t)
    d = d[d > 0]
    if not d.size:
        return None
    p = float(np.median(d))
    k = np.rint((t - t[0]) / p).astype(np.int64)
    if bool((np.diff(k) < 1).any()):
        return None
    p = _fit_period(t, k)
    if not p > 0:
        return None
    r = t - k * p
    if not float(np.ptp(r)) <= REGULAR_TOL * p:
        return None
    return Slots(k, p, float(r.min()), int(k[-1] - (t.size - 1)), True, t)


def place_messages(slots: list[Slots]) -> list[np.ndarray | None]:
    """Data times of several messages' frames: per message ``anchor + k period``, or None
    where the arrival times are kept (regular).

    Messages whose periods agree within ``SAME_RATE`` share their frame-weighted mean
    period, and their anchors are moved by whole periods to the phase of the group's
    first message: frames of one sample get one time.
    """
    out: list[np.ndarray | None] = [None] * len(slots)
    groups: list[list[int]] = []
    for j, s in enumerate(slots):
        for g in groups:
            if abs(s.period / slots[g[0]].period - 1.0) < SAME_RATE:
                g.append(j)
                break
        else:
            groups.append([j])
    for g in groups:
        if all(slots[j].regular for j in g):
            continue
        w = np.array([slots[j].k.size for j in g], dtype=np.float64)
        p = float(np.dot(w, [slots[j].period for j in g]) / w.sum())
        a0 = slots[g[0]].envelope(p)
        for j in g:
            s = slots[j]
            a = a0 + round((s.envelope(p) - a0) / p) * p
            out[j] = a + s.k * p
    return out
