"""Sample slots from arrival times (docs/can.md "Without a sensor clock"): frame ``i`` of a
message gets slot ``k_i = i + (frames missing before it)`` and data time ``a + k_i P``, ``P``
from the lower convex hull of ``(i, t_i)`` then refitted, gaps where the lower envelope of
``t_i - i P`` rises by more than half a period, ``a`` the envelope.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

#: the last frames of a message, in which a gap cannot be told from a delivery delay
TAIL = 32
#: frames per side whose least delay finds where the envelope rises (short) ...
DETECT = 32
#: ... and measures by how much (long)
SIDE = 128
#: fewest frames of a message whose arrival times are placed in slots
MIN_FRAMES = 8
#: arrival times within this fraction of a period of their slot grid are kept as they are
REGULAR_TOL = 1e-4
#: more than this fraction of intervals exactly the median: stamped by the sender's clock
STAMPED = 0.5
#: messages whose periods differ by less than this (relative) share one period and phase
SAME_RATE = 1e-3
#: a period is rounded to whole µs when that is within this many standard errors
SNAP_SE = 3.0
#: least-squares refits of the period
REFITS = 3


@dataclass
class Slots:
    """The sample slots ``k`` of one message's frames (arrival times ``t``, s): ``period`` (s), ``anchor``
    (s), frames ``missing``, ``regular`` (times kept)."""

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


def _slots(t: np.ndarray, period: float) -> np.ndarray:
    """Slots of arrival times ``t`` for a period estimate (step 2 of the module docstring)."""
    n = t.size
    u = t - np.arange(n) * period
    side = min(SIDE, n)
    # at each i the least of u[i:i+w] (ahead) and of u[i-w:i] (behind)
    w = min(DETECT, n)
    pad = np.full(w - 1, np.inf)
    behind = np.empty(n)
    behind[0] = u[0]
    behind[1:] = sliding_window_view(np.r_[pad, u], w).min(axis=1)[:n - 1]
    rise = sliding_window_view(np.r_[u, pad], w).min(axis=1) - behind
    rise[0] = 0.0
    rise[max(1, n - TAIL):] = 0.0         # the last frames: a delay, not a gap
    k = np.arange(n, dtype=np.int64)
    up = rise > 0.5 * period
    if not up.any():
        return k
    edge = np.diff(np.r_[False, up, False].astype(np.int8))
    starts = np.flatnonzero(edge == 1).tolist()
    ends = np.flatnonzero(edge == -1).tolist()
    # each rising stretch: the least u of up to SIDE frames after it above that before it
    for q, (a, b) in enumerate(zip(starts, ends)):
        lo = ends[q - 1] if q else 0
        hi = starts[q + 1] if q + 1 < len(starts) else n
        before = float(u[max(lo, a - side):a].min())
        after = float(u[b:min(hi, b + side)].min())
        g = int(np.rint((after - before) / period))
        if g > 0:
            # after the last frame of the stretch that arrived too early to be after the gap
            early = np.flatnonzero(u[a:b] < before + (g - 0.5) * period)
            k[a + (int(early[-1]) + 1 if early.size else 0):] += g
    return k


def hull_period(t: np.ndarray) -> float:
    """Slope (s per frame) of the lower convex hull of ``(i, t_i)`` under the middle frame."""
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
    """Sample slots of one message's arrival times ``t`` (s); None when they cannot be placed."""
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
            return Slots(np.arange(n, dtype=np.int64), med, float(t[0]), 0, True, t)
    p = hull_period(t)
    if not p > 0:
        return None
    k = _slots(t, p)
    for i in range(REFITS + 1):
        p = _fit_period(t, k)
        if not p > 0:
            return None
        if i < REFITS:
            k = _slots(t, p)
    # rounded to whole µs when within SNAP_SE standard errors (timers count µs)
    p_us = round(p * 1e6) / 1e6
    kc = k - k.mean()
    resid = t - t.mean() - p * kc
    se = float(np.sqrt(np.dot(resid, resid) / max(1, n - 2) / float(np.dot(kc, kc))))
    if p_us > 0 and abs(p_us - p) <= SNAP_SE * se:
        p = p_us
    r = t - k * p
    return Slots(k, p, float(r.min()), int(k[-1] - (n - 1)), False, t)


def _regular(t: np.ndarray) -> Slots | None:
    """The slots of arrival times already on a uniform grid (gaps allowed), else None."""
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
    """Data times ``anchor + k period`` of several messages' frames (None: kept); messages of one rate share
    their mean period and the first one's phase."""
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
