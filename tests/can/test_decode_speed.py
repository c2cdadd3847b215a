"""The decoder's fast paths equal the straightforward code they replace, exactly.

* :meth:`RollingBuffer.align` reads only the window's rows of each ring
  (:meth:`Source.rows_between`, by bisection while the times held are in order, a property
  checked incrementally at reads) and counts collisions without ``np.unique``: equal to
  the former snapshot-everything alignment (kept here as the reference) for random pushes,
  gaps, dropped frames, out-of-order and NaN times, clears and ring wrap-around, with
  windows sliding over the stream as the monitor's driver cuts them.
* :func:`estimator.decode.rules.counters.period_after`: the period recurrence with the
  products taken out of the loop is the scalar recurrence bit for bit, whatever the inputs.
* The candump column parser on lines of one layout (any timestamp digits, ID digits,
  payload length) equals ``float()``/``int()``/``fromhex`` line by line.
* Small ``feed_arrays`` batches, down to one frame, equal the frame-by-frame oracle.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from estimator.decode.buffer import Aligned, RollingBuffer, _gaps
from estimator.decode.rules.counters import period_after as _ema
from suspid.can import candump
from suspid.can.logs import FrameArrays
from suspid.errors import InputError
from tests.can.frame_by_frame import push_one
from tests.can.test_batch_equivalence import (RATES, _listeners, _stream, feed_in_chunks,
                                              snapshot)

_SETTINGS = settings(max_examples=80, deadline=None,
                     suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


# ---- alignment -----------------------------------------------------------------------------
def _reference_align(buf: RollingBuffer, names: list[str], dt: float | None,
                     t_start: float | None, t_end: float | None) -> Aligned:
    """The alignment as it was: a snapshot of every ring, a time mask, ``np.unique``."""
    snaps: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for c in names:
        src = buf._where[c][0]
        if src.name not in snaps:
            t, v = src.snapshot()
            keep = np.ones(t.size, dtype=bool)
            if t_start is not None:
                keep &= t >= t_start
            if t_end is not None:
                keep &= t <= t_end
            keep &= np.isfinite(t)   # a NaN/inf time is never aligned
            snaps[src.name] = (t[keep], v[keep])
    nonempty = [s for s in snaps.values() if s[0].size]
    if not nonempty:
        raise InputError("no decoded samples")
    if dt is None:
        steps = []
        for t, _ in nonempty:
            if t.size >= 2:
                d = np.diff(t)
                d = d[d > 0]
                if d.size:
                    steps.append(float(np.median(d)))
        dt = min(steps) if steps else 1.0
    t0 = min(float(t.min()) for t, _ in nonempty)
    t_last = max(float(t.max()) for t, _ in nonempty)
    n = int(np.rint((t_last - t0) / dt)) + 1
    stamps = np.full(n, np.nan)
    values: dict[str, np.ndarray] = {}
    collisions = 0
    cells: dict[str, np.ndarray] = {}
    for name, (t, v) in snaps.items():
        k = np.rint((t - t0) / dt).astype(np.int64)
        ok = (k >= 0) & (k < n)
        cells[name] = k
        kk = k[ok]
        stamps[kk] = t[ok]
        collisions = max(collisions, int(kk.size - np.unique(kk).size))
    for c in names:
        src, col = buf._where[c]
        t, v = snaps[src.name]
        k = cells[src.name]
        ok = (k >= 0) & (k < n)
        out = np.full(n, np.nan)
        out[k[ok]] = v[ok, col]
        values[c] = out
    present = ~np.isnan(stamps)
    kmax = int(np.flatnonzero(present)[-1]) if present.any() else 0
    dt_fit = (float(stamps[kmax]) - t0) / kmax if kmax > 0 else dt
    grid = t0 + np.arange(n) * dt_fit
    snapped = float(np.nanmax(np.abs(stamps - grid))) if present.any() else 0.0
    t_out = np.where(present, stamps, grid) if snapped <= 1e-9 * dt_fit else grid
    gaps = []
    for c in names:
        gaps.extend(_gaps(c, values[c], t_out))
    return Aligned(t_out, dt_fit, values, gaps, collisions, snapped)


def _bits(x: np.ndarray) -> bytes:
    return np.ascontiguousarray(x, dtype=np.float64).tobytes()


def _assert_same(a: Aligned, b: Aligned) -> None:
    assert _bits(a.t) == _bits(b.t)
    assert np.float64(a.dt).tobytes() == np.float64(b.dt).tobytes()
    assert list(a.values) == list(b.values)
    for c in a.values:
        assert _bits(a.values[c]) == _bits(b.values[c]), c
    assert [g.as_dict() for g in a.gaps] == [g.as_dict() for g in b.gaps]
    assert a.collisions == b.collisions
    assert np.float64(a.snapped).tobytes() == np.float64(b.snapped).tobytes()


_SOURCES = {"A": ["a1", "a2"], "B": ["b1"], "C": ["c1", "c2", "c3"]}


@st.composite
def _pushes(draw: st.DrawFn) -> list[tuple]:
    """Operations on a buffer: blocks of rows (one by one or push_many), reads, clears."""
    ops: list[tuple] = []
    t = draw(st.floats(-5.0, 5.0))
    for _ in range(draw(st.integers(1, 14))):
        kind = draw(st.sampled_from(["rows", "rows", "rows", "read", "read", "clear"]))
        if kind != "rows":
            ops.append((kind,))
            continue
        n = draw(st.integers(1, 70))
        # times: a 2 ms grid with dropped frames, jitter, duplicates, a late frame, a jump
        # back (a clock reset), now and then NaN
        steps = draw(st.lists(st.sampled_from([0.002, 0.002, 0.002, 0.004, 0.010, 0.0, 0.0021,
                                               0.0019, -0.003, -0.5, 0.3]),
                              min_size=n, max_size=n))
        times = []
        for s in steps:
            t += s
            times.append(t)
        if draw(st.integers(0, 9)) == 0:
            times[draw(st.integers(0, n - 1))] = math.nan
        src = draw(st.sampled_from(sorted(_SOURCES)))
        ops.append(("rows", src, times, draw(st.booleans())))
    return ops


def _windows(draw: st.DrawFn, t_hi: float) -> list[tuple[float | None, float | None]]:
    out: list[tuple[float | None, float | None]] = [(None, None)]
    w = draw(st.sampled_from([0.02, 0.05, 0.1, 0.4]))
    step = draw(st.sampled_from([0.01, 0.03, 0.05]))
    end = t_hi - 0.3
    for _ in range(draw(st.integers(1, 6))):      # sliding, overlapping, as the driver cuts
        out.append((end - w, end))
        end += step
    out.append((None, t_hi - 0.05))
    out.append((t_hi - 0.1, None))
    out.append((t_hi, t_hi - 1.0))                  # empty: start after end
    out.append((math.nan, t_hi))                    # a NaN bound takes no row
    return out


@_SETTINGS
@given(ops=_pushes(), capacity=st.sampled_from([2, 5, 16, 64]), growable=st.booleans(),
       data=st.data())
def test_align_equals_snapshot_alignment(ops: list[tuple], capacity: int, growable: bool,
                                         data: st.DataObject) -> None:
    buf = RollingBuffer(capacity, growable)
    srcs = {name: buf.source(name, chans) for name, chans in _SOURCES.items()}
    rng = np.random.default_rng(len(ops))
    t_hi = 0.0
    names = [c for chans in _SOURCES.values() for c in chans]
    for op in ops:
        if op[0] == "clear":
            srcs[data.draw(st.sampled_from(sorted(srcs)))].clear()
            continue
        if op[0] == "rows":
            _, name, times, many = op
            src = srcs[name]
            vals = rng.normal(size=(len(times), len(src.channels)))
            vals[rng.random(vals.shape) < 0.05] = math.nan
            if many:
                src.push_many(np.array(times), vals)
            else:
                for tk, row in zip(times, vals):
                    push_one(src, tk, row.tolist())
            t_hi = max([t_hi] + [x for x in times if x == x])
            continue
        for t_start, t_end in _windows(data.draw, t_hi):
            chans = data.draw(st.sampled_from([names, ["a1", "c2"], ["b1"], ["c3", "a2", "b1"]]))
            dt = data.draw(st.sampled_from([None, 0.002, 0.0025]))
            for c in {buf._where[c][0].name for c in chans}:   # the rows, as the reads see them
                src = srcs[c]
                t, v = src.snapshot()
                keep = np.ones(t.size, bool)
                if t_start is not None:
                    keep &= t >= t_start
                if t_end is not None:
                    keep &= t <= t_end
                got_t, got_v = src.rows_between(t_start, t_end, range(len(src.channels)))
                assert _bits(got_t) == _bits(t[keep])
                for j in range(len(src.channels)):
                    assert _bits(got_v[j]) == _bits(v[keep, j])
            try:
                want = _reference_align(buf, chans, dt, t_start, t_end)
            except (InputError, ValueError, MemoryError) as exc:
                with pytest.raises(type(exc)):
                    buf.align(chans, dt, t_start, t_end)
                continue
            if want.t.size > 200_000:     # a NaN/late time made a huge grid: both refuse
                continue
            _assert_same(buf.align(chans, dt, t_start, t_end), want)


@pytest.mark.parametrize("capacity", [64, 1000])
def test_sliding_windows_over_a_wrapping_ring(capacity: int) -> None:
    """The monitor's pattern: 500 Hz sources with lost frames, late frames, one clock
    reset, a ring wrapping many times; every sliding window equals the reference."""
    rng = np.random.default_rng(7)
    buf = RollingBuffer(capacity)
    a = buf.source("A", ["x", "y"])
    b = buf.source("B", ["z"])
    t = 10.0
    win, step = 0.08, 0.03
    next_end = t + win
    for k in range(3000):
        t += 0.002
        for src in (a, b):
            if rng.random() < 0.03:
                continue                                   # a lost frame
            tk = t - (0.0006 if rng.random() < 0.01 else 0.0)   # late, out of order
            push_one(src, tk, rng.normal(size=len(src.channels)).tolist())
        if k == 1500:
            t -= 2.0                                       # the logger clock jumps back
            next_end = t + win
        while t > next_end + 1e-9:
            want = _reference_align(buf, ["x", "z", "y"], 0.002, next_end - win, next_end)
            _assert_same(buf.align(["x", "z", "y"], 0.002, next_end - win, next_end), want)
            next_end += step


# ---- the period recurrence -----------------------------------------------------------------
def _ema_reference(jobs: list[tuple[float, int, int]], el: np.ndarray) -> list[float]:
    out = []
    for p, a, b in jobs:
        for x in el[a:b].tolist():
            p = 0.9 * p + 0.1 * x if p > 0 else x
        out.append(p)
    return out


_EL = st.one_of(st.floats(1e-4, 1e-2), st.sampled_from([0.0, -0.0, -0.001, math.nan, math.inf,
                                                          5e-324, 1e-310, 2e-323, 0.002]))


@settings(max_examples=300, deadline=None)
@given(el=st.lists(_EL, min_size=0, max_size=60),
       p0=st.lists(st.sampled_from([0.0, -1.0, math.nan, 0.002, 5e-324, math.inf, 1e-3]),
                   min_size=1, max_size=4),
       cuts=st.lists(st.integers(0, 60), min_size=2, max_size=8))
def test_ema_equals_scalar_recurrence(el: list[float], p0: list[float], cuts: list[int]) -> None:
    arr = np.array(el, dtype=np.float64)
    cuts = sorted(min(c, arr.size) for c in cuts)
    jobs = [(p0[k % len(p0)], a, b) for k, (a, b) in enumerate(zip(cuts[:-1], cuts[1:]))]
    got = np.array(_ema(jobs, arr), dtype=np.float64)
    want = np.array(_ema_reference(jobs, arr), dtype=np.float64)
    assert got.tobytes() == want.tobytes()


def test_ema_on_a_long_jittery_run() -> None:
    t = np.cumsum(np.round(np.random.default_rng(3).normal(0.002, 2e-5, 20000), 6)) + 1e5
    el = np.diff(t)
    jobs = [(0.0, 0, 7000), (0.002, 7000, 19999), (-1.0, 3, 3)]
    assert np.array(_ema(jobs, el)).tobytes() == np.array(_ema_reference(jobs, el)).tobytes()


# ---- candump lines of one layout ---------------------------------------------------------
@settings(max_examples=200, deadline=None)
@given(ts=st.lists(st.tuples(st.integers(0, 10**18), st.integers(1, 20), st.integers(0, 9)),
                   min_size=1, max_size=20),
       id_digits=st.integers(1, 8), nbytes=st.integers(0, 8), seed=st.integers(0, 2**32 - 1))
def test_parse_layout_equals_message_parser(ts: list[tuple[int, int, int]], id_digits: int,
                                            nbytes: int, seed: int) -> None:
    """Lines of one layout (any timestamp digits, ID digits, payload length) through the
    column parser: the frames ``float()``/``int()``/``fromhex`` give, line by line."""
    rng = np.random.default_rng(seed)
    ni = max(1, min(len(str(ts[0][0])), 20))
    nf = ts[0][1]
    lines = []
    for i, f, _ in ts:
        t = f"{i % 10 ** ni:0{ni}d}.{(i * 7919) % 10 ** nf:0{nf}d}"
        cid = int(rng.integers(0, 16 ** id_digits))
        data = bytes(rng.integers(0, 256, nbytes, dtype=np.uint8)).hex()
        data = "".join(ch.upper() if rng.random() < 0.5 else ch for ch in data)
        lines.append(f"({t}) can0 {cid:0{id_digits}X}#{data}")
    raw = "".join(lines).encode()
    rows = np.frombuffer(raw, np.uint8).reshape(len(lines), -1)
    layout = candump._line_layout(rows[0].tobytes())
    assert layout is not None
    good, t, ids, data = candump._parse_layout(rows, layout)
    assert good.all()
    for k, line in enumerate(lines):
        head, _, rest = line.partition(") can0 ")
        fid, _, payload = rest.partition("#")
        assert t[k].tobytes() == np.float64(float(head[1:])).tobytes()
        assert int(ids[k]) == int(fid, 16)
        assert data[k].tobytes() == bytes.fromhex(payload).ljust(8, b"\0")


# ---- small feed_arrays batches --------------------------------------------------------------
@_SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(20, 300), rates=RATES,
       time_source=st.sampled_from(["timestamp", "tick"]), restart=st.booleans(),
       capacity=st.sampled_from([16, 4096]),
       chunks=st.lists(st.integers(1, 400), min_size=1, max_size=6))
def test_small_array_batches_equal_frame_by_frame(seed: int, n: int, rates: dict[str, float],
                                                  time_source: str, restart: bool,
                                                  capacity: int, chunks: list[int]) -> None:
    """``feed_arrays`` in small batches (the driver's last frames before a window end), down
    to single frames -- error/remote frames, payloads longer than 8 bytes, extended IDs
    included."""
    frames = _stream(seed, n, rates, time_source == "tick", restart)
    ref, lst = _listeners(time_source, capacity, False, 4)
    for m in frames:
        ref.on_message_received(m)
    feed_in_chunks(lst, FrameArrays.from_messages(frames), chunks)
    assert snapshot(lst) == snapshot(ref)


@pytest.mark.parametrize("times", [[math.nan], [math.nan, math.nan, 0.01, math.nan, 0.016, math.nan]])
def test_rows_between_never_returns_a_nan_time(times: list[float]) -> None:
    """A NaN time as the oldest row held (never compared with a predecessor) is not 'sorted'."""
    buf = RollingBuffer(2, False)
    src = buf.source("B", ["b1"])
    for t in times:
        push_one(src, t, [1.0])
    for lo, hi in ((0.0, None), (None, 1.0), (0.0, 1.0)):
        t, v = src.rows_between(lo, hi, [0])
        assert not np.isnan(t).any() and t.size == v[0].size


def test_align_skips_rows_without_a_finite_time() -> None:
    """A NaN or inf time (possible through a direct push) is left out, not a crash."""
    buf = RollingBuffer(16, False)
    src = buf.source("A", ["a"])
    for t, v in ((0.0, 1.0), (0.002, 2.0), (math.nan, 9.0), (math.inf, 9.0), (0.004, 3.0)):
        push_one(src, t, [v])
    al = buf.align()
    np.testing.assert_allclose(al.t, [0.0, 0.002, 0.004])
    np.testing.assert_array_equal(al.values["a"], [1.0, 2.0, 3.0])
