"""The decoder's rules (estimator/decode/rules/) directly: each array form equals the
frame-by-frame form of the oracle (tests/can/frame_by_frame.py) frame by frame, and the rules
do what the docs say (lost frames, stale and jumping counters, the tick of a counter, the time
order and its re-anchoring)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from estimator.decode.rules import counters, e2e, timebase
from estimator.decode.rules.counters import FrameCounts
from suspid.can.crc import COUNTER_MODULUS, e2e_crc
from tests.can import frame_by_frame as scalar

_SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@dataclass
class _State:
    last_c: int = -1
    last_ts: float = 0.0
    period: float = 0.0
    last_arrival: float = 0.0
    sync_n: int = -1


# ---- E2E ---------------------------------------------------------------------------------
@_SETTINGS
@given(st.integers(0, 2**31 - 1), st.lists(st.tuples(st.sampled_from([0x101, 0x2A0, 0x7FF]),
                                                      st.integers(2, 8), st.booleans()),
                                            min_size=1, max_size=40))
def test_crc_rows_equal_the_scalar_check(seed: int, frames: list[tuple[int, int, bool]]) -> None:
    rng = np.random.default_rng(seed)
    b8 = np.zeros((len(frames), 8), dtype=np.uint8)
    for i, (fid, dlc, corrupt) in enumerate(frames):
        p = bytearray(rng.integers(0, 256, dlc, dtype=np.uint8).tobytes())
        p[0] = e2e_crc(fid, bytes(p))
        if corrupt:
            p[int(rng.integers(0, dlc))] ^= 1 << int(rng.integers(0, 8))
        b8[i, :dlc] = np.frombuffer(bytes(p), dtype=np.uint8)
    dlc = np.array([f[1] for f in frames])
    start = np.array([e2e.crc_start(f[0]) for f in frames], dtype=np.uint8)
    check = rng.random(len(frames)) < 0.8
    got = e2e.crc_ok_rows(b8, start, dlc, check)
    for i, (fid, n, _) in enumerate(frames):
        want = e2e_crc(fid, bytes(b8[i, :n])) == b8[i, 0] if check[i] else True
        assert got[i] == want
    rows = b8.view(np.uint64).reshape(-1)
    assert e2e.alive_counters(rows).tolist() == [int(r[1]) & 0x0F for r in b8]


# ---- counters ----------------------------------------------------------------------------
def _rules(max_delta: int = 4, stale: int = 5) -> tuple[counters.CounterRules, FrameCounts]:
    c = FrameCounts()
    return counters.CounterRules(c, max_delta, stale), c


def test_counter_rules() -> None:
    rules, c = _rules()
    s = _State()
    t = 0.0
    for k in range(20):                       # a steady stream: every frame accepted
        assert rules.step(s, k % COUNTER_MODULUS, t)
        t += 0.001
    assert math.isclose(s.period, 0.001, rel_tol=1e-9) and c.lost == 0
    last = s.last_c
    assert rules.step(s, (last + 3) % 15, t + 0.002)      # 2 lost
    assert c.lost == 2
    assert not rules.step(s, s.last_c, t + 0.0025)        # repeated: stale, state kept
    assert c.rejected["counter_stale"] == 1
    assert not rules.step(s, 15, t + 0.003)               # the invalid value
    assert c.rejected["counter_jump"] == 1
    before = s.last_c
    assert not rules.step(s, (before + 7) % 15, t + 0.003)   # a jump re-synchronises
    assert c.rejected["counter_jump"] == 2 and s.last_c == (before + 7) % 15
    # a silence of 16 periods with an advance of 1: 15 frames lost that the counter hides
    t = s.last_ts
    assert rules.step(s, (s.last_c + 1) % 15, t + 0.016)
    assert c.lost == 2 + 15


@_SETTINGS
@given(st.lists(st.tuples(st.integers(1, 3), st.floats(0.5, 1.4)), min_size=1, max_size=60),
       st.integers(0, 14), st.booleans())
def test_steady_frames_need_only_the_period_recurrence(steps: list[tuple[int, float]], c0: int,
                                                       fresh: bool) -> None:
    """Up to the first unsteady frame, step() frame by frame == period_after()."""
    c = []
    t = []
    ck, tk = c0, 1.0
    for adv, dt in steps:
        ck = (ck + adv) % COUNTER_MODULUS
        tk += dt * 1e-3
        c.append(ck)
        t.append(tk)
    s0 = _State() if fresh else _State(c0, 1.0, 1e-3)
    good, el, rid = counters.steady_frames(np.array(c), np.array(t), np.array([0]),
                                           np.array([s0.last_c]), np.array([s0.last_ts]),
                                           np.array([s0.period]))
    assert (rid == 0).all()
    fb = int(np.argmin(good)) if not good.all() else len(c)
    rules, counts = _rules()
    s = _State(s0.last_c, s0.last_ts, s0.period)
    for k in range(fb):
        assert rules.step(s, c[k], t[k])
    assert counts.lost == 0 and not any(counts.rejected.values())
    if fb:
        (p,) = counters.period_after([(s0.period, 1 if fresh else 0, fb)], el)
        assert p == s.period                               # bit for bit
        assert s.last_c == c[fb - 1] and s.last_ts == t[fb - 1]


@_SETTINGS
@given(st.floats(-1.0, 1.0), st.lists(st.floats(1e-6, 1.0), min_size=1, max_size=50))
def test_period_after_equals_the_scalar_recurrence(p0: float, xs: list[float]) -> None:
    el = np.array(xs)
    p = p0
    for x in xs:
        p = 0.9 * p + 0.1 * x if p > 0 else x
    assert counters.period_after([(p0, 0, len(xs))], el) == [p]


# ---- time base ---------------------------------------------------------------------------
@_SETTINGS
@given(st.lists(st.tuples(st.integers(0, 10**9), st.integers(0, 14)), min_size=1, max_size=50),
       st.sampled_from([500, 1000, 2000, 333]))
def test_tick_of_counter_scalar_equals_arrays(pairs: list[tuple[int, int]], period_us: int) -> None:
    st_ = np.array([p[0] for p in pairs], dtype=np.int64)
    c = np.array([p[1] for p in pairs], dtype=np.int64)
    ticks = timebase.ticks_of_counters(st_, c)
    per = np.full(len(pairs), period_us * 1e-6)
    times = timebase.tick_times(ticks, per)
    for k, (s, ck) in enumerate(pairs):
        tick = scalar.tick_of_counter(s, ck)
        assert tick == ticks[k] and tick % COUNTER_MODULUS == ck
        assert s - COUNTER_MODULUS // 2 <= tick <= s + COUNTER_MODULUS // 2
        assert scalar.tick_time(tick, period_us * 1e-6) == times[k]
    sy = timebase.sync_times(st_, np.full(len(pairs), period_us, dtype=np.int64),
                             np.zeros(len(pairs)))
    assert sy.tolist() == [s * period_us / 1e6 for s, _ in pairs]


@_SETTINGS
@given(st.lists(st.one_of(st.floats(-5, 5), st.just(math.nan), st.just(math.inf),
                          st.just(-math.inf)), min_size=1, max_size=80),
       st.lists(st.integers(1, 20), min_size=1, max_size=5))
def test_time_order_equals_frame_by_frame(ts: list[float], cuts: list[int]) -> None:
    """The array time order, in batches cut anywhere, admits exactly the frames the
    frame-by-frame rule admits, with the same state after (re-anchors included)."""
    order, one = timebase.TimeOrder(), scalar.ScalarTimeOrder()
    want = [one.admit_one(t) for t in ts]
    got: list[bool] = []
    pos = k = 0
    while pos < len(ts):
        got += order.admit(np.array(ts[pos:pos + cuts[k % len(cuts)]])).tolist()
        pos += cuts[k % len(cuts)]
        k += 1
    assert got == want
    assert (order.last, order.rejects, order.resyncs) == (one.last, one.rejects, one.resyncs)


@_SETTINGS
@given(st.lists(st.tuples(st.integers(0, 3), st.integers(-1, 4), st.floats(0, 0.05),
                          st.floats(0, 0.05), st.floats(1e-4, 3e-3), st.floats(0, 3e-3)),
                min_size=1, max_size=40))
def test_fresh_ticks_are_never_stale(rows: list[tuple[int, int, float, float, float, float]]) -> None:
    sn = np.array([r[0] for r in rows], dtype=np.int64)
    prev_sn = np.array([r[1] for r in rows], dtype=np.int64)
    arr = np.array([r[2] for r in rows])
    prev_a = np.array([r[3] for r in rows])
    per = np.array([r[4] for r in rows])
    ok = timebase.fresh_ticks(sn, prev_sn, arr, prev_a, per, np.ones(len(rows), bool))
    for k, r in enumerate(rows):
        route = _State(last_c=3, period=r[5], last_arrival=r[3], sync_n=r[1])
        if ok[k]:
            assert not timebase.stale_tick(route, r[0], r[4], r[2])


def test_choose_time_base() -> None:
    sync = np.array([0x080])
    known = np.array([0x080, 0x100, 0x101])
    assert timebase.choose_time_base(np.array([0x100, 0x080]), sync, known, False) == "tick"
    assert timebase.choose_time_base(np.array([0x100] * 10), sync, known, False) is None
    assert timebase.choose_time_base(np.array([0x100] * 10), sync, known, True) == "timestamp"
    many = np.array([0x100] * timebase.AUTO_FRAMES)
    assert timebase.choose_time_base(many, sync, known, False) == "timestamp"
    foreign = np.array([0x555] * 1000)          # foreign frames do not decide
    assert timebase.choose_time_base(foreign, sync, known, False) is None
    assert timebase.first_sync(np.array([0x100, 0x101, 0x080, 0x080]), sync) == 2
    assert timebase.first_sync(np.array([0x100]), sync) == -1
