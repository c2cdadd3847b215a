"""Bounded, preallocated rolling buffer of decoded samples, and alignment on a uniform grid.

One ring of NumPy columns per message: full, it overwrites its oldest row
(:attr:`RollingBuffer.overwritten`) or doubles (``growable``). :meth:`RollingBuffer.align`
puts channels on one grid without interpolating; empty cells stay NaN (:class:`Gap`).
"""
from __future__ import annotations

import threading
from dataclasses import asdict, dataclass, field
from typing import Iterable, Sequence

import numpy as np

from suspid.errors import InputError

#: alignment refuses grids longer than this (a timestamp outlier, not a real record) ...
MAX_GRID = 50_000_000
#: ... and grids of more than SPARSE_FREE cells SPARSE_RATIO times longer than the data
SPARSE_FREE = 2_000_000
SPARSE_RATIO = 50


@dataclass(frozen=True)
class Gap:
    """A run of ``samples`` missing cells of one channel, ``t_start`` to ``t_end`` (s)."""

    channel: str
    t_start: float
    t_end: float
    samples: int

    def as_dict(self) -> dict[str, object]:
        return asdict(self)


@dataclass
class Aligned:
    """Channels on one uniform time base: grid times ``t`` (s; the frames' own where all lie
    within 1e-9 dt of the grid) and step ``dt`` (s), ``values`` (channel -> array, NaN where no
    valid sample fell), ``gaps`` (runs of NaN per channel; for one sample every ``N`` cells: of
    ``N`` or more), ``collisions`` (samples that fell on a filled cell, the later kept; the
    most of one ring), ``snapped`` (largest snap to a cell, s) and ``collided`` (ring -> times
    (s) of its samples that fell on a cell already filled, each the later of its pair)."""

    t: np.ndarray
    dt: float
    values: dict[str, np.ndarray]
    gaps: list[Gap] = field(default_factory=list)
    collisions: int = 0
    snapped: float = 0.0
    collided: dict[str, np.ndarray] = field(default_factory=dict)


def collision_notes(counts: dict[str, int], where: object, stats: dict[str, object]) -> list[str]:
    """Record ``counts`` (ring -> samples that fell on a grid cell already filled, the later
    kept) in the frame statistics ``stats`` as ``collisions`` (the non-zero ones; none: no
    key) and return one warning per such ring, prefixed by ``where`` (the input)."""
    counts = {k: n for k, n in counts.items() if n}
    if counts:
        stats["collisions"] = counts
    return [f"{where}: {k}: {n} samples fell on a grid cell already filled; the later of "
            "each pair was kept" for k, n in counts.items()]


class NoSamplesError(InputError):
    """No accepted frame carries the asked channels in the asked span."""


class Source:
    """Ring of rows ``(t, v_0, ..., v_{k-1})`` of one message; created by :meth:`RollingBuffer.source`."""

    __slots__ = ("name", "group", "channels", "t", "cols", "w", "n", "cap", "growable",
                 "overwritten", "_lock", "_cleared", "_checked", "_drop")

    def __init__(self, name: str, channels: Sequence[str], capacity: int, growable: bool,
                 lock: threading.Lock, group: str | None = None) -> None:
        self.name = name
        #: the message whose frames fill this ring (a page's: its message's)
        self.group = name if group is None else group
        self.channels = tuple(channels)
        self.cap = capacity
        self.t = np.zeros(capacity)   # calloc'd: pages are mapped as rows are written
        self.cols = tuple(np.zeros(capacity) for _ in self.channels)
        self.w = 0          # next write index
        self.n = 0          # rows held (<= cap)
        self.growable = growable
        self.overwritten = 0
        # time order, checked at reads (rows numbered in push order): rows cleared, rows
        # checked, the newest row whose time is not >= its predecessor's (-1: none)
        self._cleared = 0
        self._checked = 0
        self._drop = -1
        self._lock = lock

    def _grow(self, cap: int) -> None:
        """Enlarge the columns to ``cap`` rows (zeros appended); caller holds the lock."""
        more = np.zeros(cap - self.cap)
        self.t = np.concatenate([self.t, more])
        self.cols = tuple(np.concatenate([col, more]) for col in self.cols)
        self.cap = cap

    def push_many(self, t: np.ndarray, values: np.ndarray | Sequence[np.ndarray]) -> None:
        """Append rows ``(t[i], values[i, :])`` in order: a growable ring doubles each time its
        write index reaches the end, a fixed one overwrites its oldest rows (``overwritten``)."""
        m = int(np.shape(t)[0])
        if m == 0:
            return
        cols = [values[:, j] for j in range(len(self.cols))] if isinstance(values, np.ndarray) \
            else list(values)
        if len(cols) != len(self.cols):
            raise ValueError(f"{self.name}: {len(cols)} value columns for {len(self.cols)} channels")
        with self._lock:
            cap = self.cap
            if self.growable:
                need = self.w + m
                if need >= cap:   # doubled each time the write index reaches the end
                    while cap <= need:
                        cap *= 2
                    self._grow(cap)
            elif self.n + m > cap:
                self.overwritten += self.n + m - cap
            skip = max(0, m - cap)          # rows overwritten within this block itself
            p = (self.w + skip) % cap
            c = m - skip
            first = min(c, cap - p)
            for view, src in zip((self.t, *self.cols), (t, *cols)):
                view[p:p + first] = src[skip:skip + first]
                if first < c:
                    view[:c - first] = src[skip + first:]
            self.w = (self.w + m) % cap if not self.growable else self.w + m
            self.n = min(cap, self.n + m)

    def snapshot(self) -> tuple[np.ndarray, np.ndarray]:
        """Copies ``(t (n,), values (n, k))`` in arrival order (oldest first)."""
        k = len(self.cols)
        t, v = self.rows_between(None, None, range(k))
        return t, np.column_stack([v[j] for j in range(k)]) if k else np.empty((t.size, 0))

    def _in_order(self) -> bool:
        """Whether the rows held have non-decreasing times (caller holds the lock; each row checked once)."""
        n, cap = self.n, self.cap
        total = self.overwritten + n + self._cleared
        first = total - n                         # number of the oldest row held
        lo = max(self._checked, first + 1)        # rows to compare with their predecessor
        if lo < total:
            pos = (self.w - (total - lo) - 1 + np.arange(total - lo + 1)) % cap
            t = self.t[pos]
            bad = np.flatnonzero(~(t[1:] >= t[:-1]))   # NaN too
            del t
            if bad.size:
                self._drop = lo + int(bad[-1])
        self._checked = total
        if self._drop > first:
            return False
        if n:   # the oldest row has no predecessor: a NaN there would break bisection
            t0 = self.t[(self.w - n) % cap]
            return t0 == t0
        return True

    def rows_between(self, t_start: float | None, t_end: float | None,
                     cols: Sequence[int]) -> tuple[np.ndarray, dict[int, np.ndarray]]:
        """Copies of the times and ``{column: values}`` of the rows with ``t_start <= t <= t_end``."""
        with self._lock:
            n, w, cap = self.n, self.w, self.cap
            tv = self.t
            if n < cap or w == 0:
                lo = w - n if n < cap else 0
                spans = [(lo, lo + n)]
            else:
                spans = [(w, cap), (0, w)]    # wrapped: the oldest rows from w on
            pick: list[slice | np.ndarray] = []
            if t_start is None and t_end is None:
                pick = [slice(a, b) for a, b in spans]
            elif (t_start is None or t_start == t_start) and (t_end is None or t_end == t_end) \
                    and self._in_order():
                for a, b in spans:
                    part = tv[a:b]
                    i = 0 if t_start is None else int(np.searchsorted(part, t_start, "left"))
                    j = b - a if t_end is None else int(np.searchsorted(part, t_end, "right"))
                    if i < j:
                        pick.append(slice(a + i, a + j))
            else:
                for a, b in spans:
                    part = tv[a:b]
                    keep = np.ones(part.shape, dtype=bool)   # one bound at least is set
                    if t_start is not None:
                        keep &= part >= t_start
                    if t_end is not None:
                        keep &= part <= t_end
                    if keep.any():
                        pick.append(np.flatnonzero(keep) + a)
            if not pick:
                pick = [slice(0, 0)]

            def take(view: np.ndarray) -> np.ndarray:
                if len(pick) == 1:
                    got = view[pick[0]]
                    return got.copy() if isinstance(pick[0], slice) else got
                return np.concatenate([view[p] for p in pick])

            t = take(tv)
            vals = {j: take(self.cols[j]) for j in cols}
        return t, vals

    def clear(self) -> None:
        """Forget every row (capacity kept)."""
        with self._lock:
            self._cleared += self.n
            self.w = 0
            self.n = 0


class RollingBuffer:
    """Bounded rolling store of decoded channels, one preallocated ring of ``capacity`` rows per message;
    ``growable``: double a full ring instead of overwriting."""

    def __init__(self, capacity: int = 1 << 16, growable: bool = False) -> None:
        if capacity < 2:
            raise ValueError(f"buffer capacity must be >= 2 rows, got {capacity}")
        self.capacity = int(capacity)
        self.growable = growable
        self.sources: dict[str, Source] = {}   # message name -> ring
        self._where: dict[str, tuple[Source, int]] = {}
        self._lock = threading.Lock()

    def source(self, name: str, channels: Sequence[str], group: str | None = None) -> Source:
        """Create (or return) the ring of message ``name`` (``group``: a multiplexed page's message)."""
        if name in self.sources:
            return self.sources[name]
        for ch in channels:
            if ch in self._where:
                raise ValueError(f"channel {ch!r} already comes from {self._where[ch][0].name}")
        src = Source(name, channels, self.capacity, self.growable, self._lock, group)
        self.sources[name] = src
        for k, ch in enumerate(channels):
            self._where[ch] = (src, k)
        return src

    @property
    def channels(self) -> list[str]:
        """Every channel held."""
        return list(self._where)

    @property
    def overwritten(self) -> int:
        """Rows lost because a ring was full (0 with ``growable``)."""
        return sum(s.overwritten for s in self.sources.values())

    def latest_time(self) -> float:
        """Time (s) of the newest row of any source (NaN if empty)."""
        best = float("nan")
        with self._lock:
            for s in self.sources.values():
                if s.n:
                    t = s.t[(s.w - 1) % s.cap]
                    if not best >= t:
                        best = t
        return best

    def earliest_time(self) -> float:
        """Time (s) of the oldest row held of any source (NaN if empty)."""
        best = float("nan")
        with self._lock:
            for s in self.sources.values():
                if s.n:
                    t = s.t[(s.w - s.n) % s.cap] if not s.growable else s.t[s.w - s.n]
                    if not best <= t:
                        best = t
        return best

    def series(self, channel: str) -> tuple[np.ndarray, np.ndarray]:
        """``(t, v)`` of one channel in arrival order."""
        src, k = self._where[channel]
        t, v = src.snapshot()
        return t, v[:, k]

    def align(self, channels: Iterable[str] | None = None, dt: float | None = None,
              t_start: float | None = None, t_end: float | None = None) -> Aligned:
        """Put ``channels`` (default all) on one uniform grid of step ``dt`` (s; default the
        smallest median frame interval of the messages) without interpolating, the rows from
        ``t_start`` to ``t_end`` (s, inclusive; default everything held). InputError for no data
        or a grid far longer than the data (a timestamp outlier)."""
        names = list(channels) if channels is not None else self.channels
        unknown = [c for c in names if c not in self._where]
        if unknown:
            raise KeyError(f"channel(s) not in buffer: {', '.join(unknown)}")
        # per source: the window's rows, only the columns asked for
        want: dict[str, tuple[Source, list[int]]] = {}
        for c in names:
            src, k = self._where[c]
            cols = want.setdefault(src.name, (src, []))[1]
            if k not in cols:
                cols.append(k)
        snaps: dict[str, tuple[np.ndarray, dict[int, np.ndarray]]] = {}
        for name, (src, cols) in want.items():
            t, v = src.rows_between(t_start, t_end, cols)
            fin = np.isfinite(t)
            if not fin.all():   # a NaN/inf time has no place on a grid
                t = t[fin]
                v = {j: x[fin] for j, x in v.items()}
            snaps[name] = (t, v)
        nonempty = [s for s in snaps.values() if s[0].size]
        if not nonempty:
            raise NoSamplesError("no decoded samples to align (no accepted frame carries the channels "
                             f"{', '.join(names)})")
        if dt is None:
            steps = []
            by_group: dict[str, list[np.ndarray]] = {}
            for name, (t, _) in snaps.items():
                if t.size:
                    by_group.setdefault(want[name][0].group, []).append(t)
            for ts in by_group.values():
                t = ts[0] if len(ts) == 1 else np.sort(np.concatenate(ts))
                if t.size >= 2:
                    d = np.diff(t)
                    d = d[d > 0]
                    if d.size:
                        steps.append(float(np.median(d)))
            dt = min(steps) if steps else 1.0
        if not dt > 0:
            raise ValueError(f"grid step must be > 0 s, got {dt}")
        # the grid is anchored on the first frame inside the window
        t0 = min(float(t.min()) for t, _ in nonempty)
        t_last = max(float(t.max()) for t, _ in nonempty)
        span = (t_last - t0) / dt
        rows = max(t.size for t, _ in nonempty)
        if span > MAX_GRID or (span > SPARSE_FREE and span > SPARSE_RATIO * rows):
            big = max(((float(np.max(np.abs(np.diff(t)))) if t.size > 1 else 0.0), name)
                      for name, (t, _) in snaps.items() if t.size)
            raise InputError(f"decoded frames span {t_last - t0:.6g} s ({t0:.6g} .. "
                             f"{t_last:.6g}), {span:.3g} grid samples of {dt:.6g} s for "
                             f"{rows} frames per message; expected at most "
                             f"{min(MAX_GRID, max(SPARSE_FREE, SPARSE_RATIO * rows)):.3g} "
                             f"(a timestamp outlier? largest step {big[0]:.6g} s in {big[1]})")
        n = int(np.rint(span)) + 1
        stamps = np.full(n, np.nan)
        values: dict[str, np.ndarray] = {}
        collisions = 0
        cells: dict[str, np.ndarray] = {}
        collided: dict[str, np.ndarray] = {}
        filled = np.zeros(n, dtype=bool)
        for name, (t, _) in snaps.items():
            kk = cells[name] = np.rint((t - t0) / dt).astype(np.int64)   # t0 <= t <= t_last
            stamps[kk] = t
            if kk.size:   # frames minus distinct cells
                filled[:] = False
                filled[kk] = True
                extra = int(kk.size - np.count_nonzero(filled))
                collisions = max(collisions, extra)
                if extra:   # the later of each pair on one cell, in push order
                    o = np.argsort(kk, kind="stable")
                    collided[name] = t[o[1:][kk[o[1:]] == kk[o[:-1]]]]
        for c in names:
            src, col = self._where[c]
            out = np.full(n, np.nan)
            out[cells[src.name]] = snaps[src.name][1][col]
            values[c] = out
        present = ~np.isnan(stamps)
        kmax = int(np.flatnonzero(present)[-1]) if present.any() else 0
        dt_fit = (float(stamps[kmax]) - t0) / kmax if kmax > 0 else dt
        grid = t0 + np.arange(n) * dt_fit
        snapped = float(np.nanmax(np.abs(stamps - grid))) if present.any() else 0.0
        if snapped <= 1e-9 * dt_fit:
            t_out = np.where(present, stamps, grid)
        else:
            t_out = grid
        gaps: list[Gap] = []
        for c in names:
            gaps.extend(_gaps(c, values[c], t_out))
        return Aligned(t_out, dt_fit, values, gaps, collisions, snapped, collided)


def cadence(v: np.ndarray) -> int:
    """Grid cells from one sample (non-NaN value of ``v``) to the next: the median distance."""
    n = v.size
    ok = ~np.isnan(v)
    p = int(np.count_nonzero(ok))
    if p < 2 or 3 * (p - 1) > 2 * (n - 1):
        return 1
    return max(1, int(np.median(np.diff(np.flatnonzero(ok)))))


def _gaps(channel: str, v: np.ndarray, t: np.ndarray) -> list[Gap]:
    """Runs of NaN of ``v`` as Gap records (of ``N`` cells or more for a :func:`cadence` of ``N``)."""
    miss = np.isnan(v)
    if not miss.any():
        return []
    d = np.diff(np.r_[0, miss.astype(np.int8), 0])
    starts = np.flatnonzero(d == 1)
    ends = np.flatnonzero(d == -1) - 1
    every = cadence(v)
    if every > 1:
        long = ends - starts + 1 >= every
        starts, ends = starts[long], ends[long]
    return [Gap(channel, float(t[a]), float(t[b]), int(b - a + 1)) for a, b in zip(starts, ends)]
