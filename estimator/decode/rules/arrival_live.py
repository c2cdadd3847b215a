"""Sample slots from arrival times, causally (the live version of :mod:`.arrival`): per
message a warm-up placed by the offline rule, then ``HOLD`` frames of look-ahead; every frame
merged back into time order (:class:`LivePlacer`). docs/can.md "Without a sensor clock".
"""
from __future__ import annotations

import copy
import heapq
import math
from collections import deque
from typing import Any

import can
import numpy as np

from estimator.decode.routes import EXT
from estimator.decode.rules.arrival import (DETECT, MIN_FRAMES, SAME_RATE, SIDE, SNAP_SE,
                                            arrival_slots)

#: frames of a message placed by the offline rule before the online rule takes over
WARMUP = 1024
#: a slow message's warm-up ends after this span of arrival time (s) instead
WARMUP_S = 2.0
#: an arrival time this far (s) before the newest is a clock reset: the rule starts over
RESET_S = 1.0
#: frames of a message held before they are released (the look-ahead)
HOLD = SIDE
#: the period is refitted every this many released frames
REFIT_EVERY = 16
#: the anchor moves down only by more than this many periods
ANCHOR_TOL = 0.25
#: released frames per point of the lower envelope the period is fitted to
BLOCK = 8
#: a message silent for this many periods (and ``SILENT_S``) no longer holds the merge back
SILENT_PERIODS = 64
SILENT_S = 0.25


class LiveSlots:
    """The online slot rule of one message (see the module docstring)."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.state = "warmup"                       # "warmup", "placing", "kept"
        self.warm: list[tuple[float, Any]] = []
        self.hold: deque[tuple[float, Any]] = deque()
        self.recent: deque[tuple[float, int]] = deque(maxlen=HOLD)
        self.period = 0.0
        self.anchor = math.inf
        self.k_last = -1
        self.missing = 0
        self.released = 0
        self.last_time = -math.inf                  # data time of the last released frame
        self.last_arrival = -math.inf
        self._sums = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # n, k, t, kk, kt, tt (origin below)
        self._t0 = 0.0
        self.se = math.inf                          # standard error of the period (s)
        self._block: tuple[float, int, float] = (math.inf, 0, 0.0)
        #: phase of the rate group: (leader, whole periods from the leader's anchor)
        self.leader: LiveSlots | None = None
        self.offset = 0
        #: arrival times and slots of the frames placed at the end of the warm-up
        self.first: tuple[np.ndarray, np.ndarray] | None = None

    def push(self, t: float, frame: Any, out: list[tuple[float, int, Any]]) -> bool:
        """Take one frame arrived at ``t`` (s), release frames to ``out``; True: warm-up ended."""
        self.last_arrival = t
        if self.state == "kept":
            out.append((t, -1, frame))
            return False
        if self.state == "warmup":
            self.warm.append((t, frame))
            if len(self.warm) < WARMUP and not (
                    t - self.warm[0][0] > WARMUP_S and len(self.warm) >= 2 * MIN_FRAMES):
                return False
            self._start(out)
            return True
        self.hold.append((t, frame))
        if len(self.hold) > HOLD:
            self._release(out)
        return False

    def _start(self, out: list[tuple[float, int, Any]], final: bool = False) -> None:
        """Place the warm-up by the offline rule (``final``: the input ended, hold none)."""
        warm, self.warm = self.warm, []
        ts = np.array([w[0] for w in warm])
        sl = arrival_slots(ts)
        if sl is None or sl.regular:
            self.state = "kept"
            if sl is not None and not final:
                self.period = sl.period
            out.extend((t, -1, f) for t, f in warm)
            return
        self.state = "placing"
        self.period = sl.period
        self._t0 = float(ts[0])
        n_out = len(warm) if final else len(warm) - min(HOLD, len(warm) // 2)
        for i in range(n_out):
            self._take(float(ts[i]), int(sl.k[i]))
        if not final:
            self._refit()
        self.anchor = float(np.min(ts[:n_out] - sl.k[:n_out] * self.period))
        self.missing = int(sl.k[n_out - 1]) - (n_out - 1)
        for i in range(n_out):
            out.append((math.nan, int(sl.k[i]), warm[i][1]))
        self.first = (ts[:n_out], sl.k[:n_out])
        self.hold.extend(warm[n_out:])

    def _take(self, t: float, k: int) -> None:
        """Book one released frame (slot ``k``, arrival ``t``) into the period's fit."""
        self.k_last = k
        self.released += 1
        self.recent.append((t, k))
        tt = t - self._t0
        u = tt - k * self.period
        if u < self._block[0]:
            self._block = (u, k, tt)
        if self.released % BLOCK == 0:
            _, kb, tb = self._block
            self._block = (math.inf, 0, 0.0)
            s = self._sums
            s[0] += 1.0
            s[1] += kb
            s[2] += tb
            s[3] += float(kb) * kb
            s[4] += kb * tb
            s[5] += tb * tb

    def _release(self, out: list[tuple[float, int, Any]]) -> None:
        """Release the oldest held frame in its slot."""
        p = self.period
        t, frame = self.hold.popleft()
        k = self.k_last + 1
        u0 = t - k * p
        # the least u of DETECT frames ahead (this one on, counted consecutive) and behind
        recent = self.recent
        nr = len(recent)
        near_b = min(recent[i][0] - recent[i][1] * p for i in range(max(0, nr - DETECT), nr))
        lim = near_b + 0.5 * p
        rises = u0 > lim
        if rises:   # ... when all of the next DETECT frames lie above
            for j, (th, _) in enumerate(self.hold, 1):
                if j >= DETECT:
                    break
                if th - (k + j) * p <= lim:
                    rises = False
                    break
        if rises:
            # a gap of g frames: the frames beyond the next DETECT against the last released
            near_a = u0
            far = math.inf
            for j, (th, _) in enumerate(self.hold, 1):
                if j < DETECT:
                    near_a = min(near_a, th - (k + j) * p)
                else:
                    far = min(far, th - (k + j) * p)
            ahead = min(near_a, far) if len(self.hold) < DETECT else far
            before = min(tr - kr * p for tr, kr in recent)
            # what the period's uncertainty can lift u over the two sides is not a gap
            slack = SNAP_SE * self.se * (len(recent) + len(self.hold) + 1)
            g = int(math.floor((ahead - before - slack) / p + 0.5))
            if g > 0:
                # the gap lies after the frames that arrived too early to be after it
                early = before + (g - 0.5) * p
                late = u0 >= early
                for j, (th, _) in enumerate(self.hold, 1):
                    if j >= DETECT or not late:
                        break
                    late = th - (k + j) * p >= early
                if late:
                    k += g
                    self.missing += g
        self._take(t, k)
        if self.released % REFIT_EVERY == 0:
            self._refit()
        self._lower(t - k * self.period)
        out.append((self.place(k), k, frame))

    def _refit(self) -> None:
        """Refit the period; the anchor moves so that the newest slot keeps its data time."""
        n, sk, st, skk, skt, stt = self._sums
        den = n * skk - sk * sk
        if n < 3 or not den > 0:
            return
        p = (n * skt - sk * st) / den
        if not p > 0:
            return
        b = (st - p * sk) / n
        sse = max(0.0, stt - 2 * b * st - 2 * p * skt + n * b * b + 2 * b * p * sk
                  + p * p * skk)
        self.se = se = math.sqrt(sse / max(1.0, n - 2) / (den / n))
        p_us = round(p * 1e6) / 1e6
        if p_us > 0 and abs(p_us - p) <= SNAP_SE * se:
            p = p_us
        if p != self.period:
            self.anchor += self.k_last * (self.period - p)
            self.period = p

    def flush(self, out: list[tuple[float, int, Any]]) -> None:
        """The input ended: place a warm-up that did not fill, release the held frames."""
        if self.state == "warmup" and self.warm:
            self._start(out, final=True)
            return
        while self.hold:
            # the last frames: a gap cannot be told from a delay, they are consecutive
            t, frame = self.hold.popleft()
            k = self.k_last + 1
            self._take(t, k)
            self._lower(t - k * self.period)
            out.append((self.place(k), k, frame))

    def _lower(self, u: float) -> None:
        """Take ``u = t - k P`` into the anchor if it drops more than ``ANCHOR_TOL`` periods below."""
        if u < self.anchor - ANCHOR_TOL * self.period:
            self.anchor = u

    def place(self, k: int) -> float:
        """Data time (s) of a released frame in slot ``k`` (never before the last one)."""
        tm = max(self.time_of(k), self.last_time)
        self.last_time = tm
        return tm

    def time_of(self, k: int) -> float:
        """Data time (s) of slot ``k``: own anchor and period, or the rate group's."""
        lead = self.leader
        if lead is None or lead is self:
            return self.anchor + k * self.period
        return lead.anchor + (self.offset + k) * lead.period

    def next_time(self) -> float:
        """Earliest data time a frame of this message can still be released with."""
        if self.state == "warmup":
            return self.warm[0][0] - 1.0 if self.warm else math.inf
        if self.state == "kept":
            return self.last_arrival
        return self.last_time

    def stats(self) -> dict[str, object]:
        """``period``, ``missing``, ``retimed`` (as the offline ``arrival_slots`` stats)."""
        lead = self.leader if self.leader is not None else self
        return {"period": lead.period if self.state == "placing" else self.period,
                "missing": self.missing, "retimed": self.state == "placing"}


class LivePlacer:
    """Place a live stream's data frames in their sample slots, every frame in time order."""

    def __init__(self, names: dict[int, str]) -> None:
        self.msgs = {k: LiveSlots(n) for k, n in names.items()}
        self._heap: list[tuple[float, int, bool, Any]] = []
        self._last_out = -math.inf
        self._first = -math.inf
        self._seq = 0
        self._newest = -math.inf
        self._groups: list[LiveSlots] = []

    def push(self, frame: can.Message) -> list[can.Message]:
        """Take one frame; returns the frames that may go to the decoder now, in time order."""
        t = _time_of(frame)
        if not math.isfinite(t):   # the time check rejects it
            self._add(t, frame, False)
            return self._drain(False)
        if t < self._newest - RESET_S:   # a clock reset: pass on everything, start over
            done = self.finish()
            self.msgs = {k: LiveSlots(ls.name) for k, ls in self.msgs.items()}
            self._groups = []
            self._last_out = self._newest = self._first = -math.inf
            return done + self.push(frame)
        self._newest = max(self._newest, t)
        if self._first == -math.inf:
            self._first = t
        key = _key_of(frame)
        ls = self.msgs.get(key) if key is not None else None
        if ls is None:
            self._add(t, frame, False)
        else:
            rel: list[tuple[float, int, Any]] = []
            if ls.push(t, frame, rel):
                self._join(ls)
            self._take(ls, rel)
        return self._drain(False)

    def finish(self) -> list[Any]:
        """The input ended: every frame still held, in time order."""
        for ls in self.msgs.values():
            was = ls.state
            rel: list[tuple[float, int, Any]] = []
            ls.flush(rel)
            if was == "warmup" and ls.state == "placing":
                self._join(ls)
            self._take(ls, rel)
        return self._drain(True)

    def stats(self) -> dict[str, dict[str, object]]:
        """Per message name: what was done (messages past their warm-up)."""
        return {ls.name: ls.stats() for ls in self.msgs.values() if ls.state != "warmup"}

    def _take(self, ls: LiveSlots, rel: list[tuple[float, int, Any]]) -> None:
        """Queue the frames a message released (see :meth:`LiveSlots.push`)."""
        placing = ls.state == "placing"
        for tm, k, fr in rel:
            if k >= 0 and math.isnan(tm):
                tm = ls.place(k)
            self._add(tm, fr, placing and k >= 0)
        ls.first = None

    def _join(self, ls: LiveSlots) -> None:
        """A message just placed joins the rate group of the first with its period."""
        if ls.state != "placing":
            return
        for lead in self._groups:
            if abs(ls.period / lead.period - 1.0) < SAME_RATE:
                env = ls.anchor if ls.first is None else \
                    float(np.min(ls.first[0] - ls.first[1] * lead.period))
                ls.offset = int(round((env - lead.anchor) / lead.period))
                ls.leader = lead
                return
        ls.leader = ls
        self._groups.append(ls)

    def _add(self, tm: float, frame: Any, moved: bool) -> None:
        heapq.heappush(self._heap, (tm if math.isfinite(tm) else -math.inf, self._seq, moved,
                                    frame))
        self._seq += 1

    def _drain(self, all_: bool) -> list[Any]:
        """Frames no message can still release an earlier frame than."""
        heap = self._heap
        if not heap:
            return []
        mark = math.inf
        for ls in () if all_ else self.msgs.values():
            if ls.state == "warmup" and not ls.warm:
                if self._newest - self._first <= SILENT_S:
                    return []     # a message not seen yet may still start before
            elif ls.state != "kept" and self._newest - ls.last_arrival <= max(
                    SILENT_S, SILENT_PERIODS * ls.period):
                mark = min(mark, ls.next_time())
        out = []
        while heap and heap[0][0] <= mark:
            tm, _, moved, frame = heapq.heappop(heap)
            if moved:   # never behind a frame already passed on
                tm = max(tm, self._last_out)
                frame = retimed(frame, tm)
            if tm > self._last_out:
                self._last_out = tm
            out.append(frame)
        return out


def _key_of(msg: can.Message) -> int | None:
    """Route key of a frame (None: error and remote frames, which carry no data)."""
    if msg.is_error_frame or msg.is_remote_frame:
        return None
    return msg.arbitration_id | EXT if msg.is_extended_id else msg.arbitration_id


def _time_of(msg: can.Message) -> float:
    """Arrival time (s) of a frame (NaN when it has none the rule can use)."""
    try:
        return float(msg.timestamp)
    except (TypeError, ValueError):
        return float("nan")


def retimed(msg: can.Message, tm: float) -> can.Message:
    """A copy of a python-can message with timestamp ``tm`` (s)."""
    m = copy.copy(msg)
    m.timestamp = tm
    return m

