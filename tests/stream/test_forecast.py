"""Trend tracking, alerts from the tracker, and forecasts of the limit crossing."""
from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from estimator.alerts import (AlertConfig, AlertEngine, AlertStore, ForecastEngine,
                              ForecastEvent, Trend, crossing, linear_trend)
from estimator.stream.tracker import TrendTracker


def test_crossing_of_an_exact_trend_and_none_for_stable_or_rising() -> None:
    tr = Trend(10.0, 1000.0, -10.0, 1e-9, 0.0, 1e-12)
    c = crossing(tr, 700.0)
    assert c is not None and c.t == pytest.approx(40.0) and c.low == pytest.approx(40.0, abs=1e-3)
    assert c.high == pytest.approx(40.0, abs=1e-3)
    # rate not significant at 90 %: no prediction; moving away: none either
    assert crossing(Trend(0.0, 1000.0, -1.0, 25.0, 0.0, 1.0), 700.0) is None
    assert crossing(Trend(0.0, 1000.0, +5.0, 25.0, 0.0, 0.01), 700.0) is None


def test_linear_trend_interval_covers_the_true_crossing_about_90_percent() -> None:
    """Straight-line wear, noisy estimates: the 90 % interval holds the truth in 80-97 %."""
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 30.0, 1.5)
    truth = 1000.0 - 5.0 * t            # crosses 700 at t = 60
    hits = 0
    n = 300
    for _ in range(n):
        y = truth + rng.normal(0.0, 10.0, t.size)
        c = crossing(linear_trend(t, y, np.full(t.size, 10.0)), 700.0)
        assert c is not None and c.low <= c.t <= c.high
        hits += c.low <= 60.0 <= c.high
    assert 0.80 <= hits / n <= 0.97


def test_tracker_refers_window_estimates_to_the_window_end() -> None:
    """Window estimates describe the window middle (t - 2 s): the tracked value at t follows
    the truth at t, the raw estimate lags by the half window."""
    tr = TrendTracker(lag=2.0, overlap=2.0, nominal={"c1": 1500.0})
    rate = -6.0
    out = {}
    for t in np.arange(4.0, 60.0, 2.0):
        mid = 1500.0 + rate * (t - 2.0)
        out = tr.update(float(t), {"c1": mid}, {"c1": 5.0})
    t_end = 58.0
    assert out["c1"]["value"] == pytest.approx(1500.0 + rate * t_end, abs=3.0)
    assert out["c1"]["rate"] == pytest.approx(rate, rel=0.05)
    assert out["c1"]["rate_stderr"] < 3.75  # 0.25 %/s of nominal: the rate random walk


def _engine() -> ForecastEngine:
    return ForecastEngine({"c1": 1050.0}, {"c1": 1500.0}, horizon_s=60.0, model="quarter2",
                          units={"c1": "N s/m"})


def test_stable_part_gets_no_forecast_and_recovering_one_withdraws_it() -> None:
    rng = np.random.default_rng(3)
    eng = _engine()
    tr = TrendTracker(lag=1.5, overlap=2.0, nominal={"c1": 1500.0})
    for t in np.arange(3.0, 200.0, 1.5):     # stable: noise only
        tr.update(float(t), {"c1": 1500.0 + rng.normal(0.0, 7.5)}, {"c1": 7.5})
        eng.update(tr.trends(float(t)))
    assert eng.emitted == []
    # wearing at 0.67 %/s (to 1245 N s/m): a forecast once the new rate has settled (the
    # tracker widens the forecast's rate uncertainty for a few windows after the kink); then
    # the damper is replaced: withdrawn
    v = 1500.0
    for t in np.arange(200.0, 225.0, 1.5):
        v -= 10.0 * 1.5
        tr.update(float(t), {"c1": v + rng.normal(0.0, 7.5)}, {"c1": 7.5})
        eng.update(tr.trends(float(t)))
    kinds = [e.kind for e in eng.emitted]
    assert kinds and kinds[0] == "forecast"
    first = eng.emitted[0]
    assert first.crossing_t is not None and first.crossing_t > first.t
    assert "will cross 70 % of nominal" in first.message
    for t in np.arange(225.0, 320.0, 1.5):
        tr.update(float(t), {"c1": 1500.0 + rng.normal(0.0, 7.5)}, {"c1": 7.5})
        eng.update(tr.trends(float(t)))
    assert eng.emitted[-1].kind == "forecast_withdrawn"
    assert "withdrawn" in eng.emitted[-1].message


def test_forecasts_survive_the_alert_store(tmp_path) -> None:
    ev = ForecastEvent("forecast", 30.0, "c1", 1200.0, -5.0, 0.5, 1050.0, 1500.0, 60.0, 55.0,
                       66.0, "quarter2", "N s/m")
    path = tmp_path / "alerts.jsonl"
    with AlertStore(path) as st:
        assert st.is_new(ev)
        st.append(ev)
    d = json.loads(path.read_text())
    assert d["type"] == "forecast" and d["crossing_t_low"] == 55.0
    with AlertStore(path) as st:
        assert st.skipped_lines == 0 and not st.is_new(ev)
        assert st.last_forecast["c1"].crossing_t == 60.0 and st.last_event == {}


@pytest.mark.slow
def test_estimator_does_not_import_the_cli() -> None:
    code = ("import sys; import estimator.stream.pipeline, estimator.stream.compare, "
            "estimator.output_only, estimator.ekf.stream; "
            "bad = [m for m in sys.modules if m.startswith('suspid.cli')]; print(bad)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"


def _track_errors(tr: TrendTracker, truth, noise: float, stated: float, t: np.ndarray,
                  seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Feed ``truth(t) + noise`` with stated stderr ``stated``; the tracked value's errors
    (against the truth at t), its stderrs and its rates."""
    rng = np.random.default_rng(seed)
    err, se, rate = [], [], []
    for ti in t:
        mid = truth(ti - tr.lag)
        out = tr.update(float(ti), {"c1": mid + rng.normal(0.0, noise)}, {"c1": stated})["c1"]
        err.append(out["value"] - truth(ti))
        se.append(out["stderr"])
        rate.append(out["rate"])
    return np.array(err), np.array(se), np.array(rate)


def test_steady_part_is_averaged_over_many_windows() -> None:
    """A stable part with 0.5 % window noise: after 30 s the tracked value's RMS error is
    below 0.6 x the window noise -- a single rate random walk large enough to follow a
    starting wear (1e-3 /s/sqrt(s)) keeps about twice as much."""
    t = np.arange(3.0, 150.0, 1.5)
    errs = {}
    for name, tr in (("imm", TrendTracker(lag=1.5, overlap=2.0, nominal={"c1": 1500.0})),
                     ("single", TrendTracker(lag=1.5, overlap=2.0, nominal={"c1": 1500.0},
                                             q_level=0.002, q_rate=1e-3, q_rate_change=0.0,
                                             calibrate=False))):
        e, _, _ = _track_errors(tr, lambda x: 1500.0, 7.5, 7.5, t, seed=5)
        errs[name] = float(np.sqrt(np.mean(e[t > 30.0] ** 2)))
    assert errs["imm"] < 0.6 * 7.5
    assert errs["imm"] < 0.7 * errs["single"]


def test_starting_wear_is_followed_by_the_changing_model() -> None:
    """Stable for 60 s, then -0.5 %/s: from 15 s after the start on, the tracked rate is
    within 35 % of the truth (its mean within 15 %), earlier than with the steady model
    alone."""
    tr = TrendTracker(lag=1.5, overlap=2.0, nominal={"c1": 1500.0})
    t = np.arange(3.0, 90.0, 1.5)

    def truth(x: float) -> float:
        return 1500.0 - 7.5 * max(0.0, x - 60.0)

    _, _, rate = _track_errors(tr, truth, 7.5, 7.5, t, seed=6)
    late = rate[(t >= 75.0)]
    assert np.all(np.abs(late + 7.5) < 0.35 * 7.5)
    assert abs(float(np.mean(late)) + 7.5) < 0.15 * 7.5
    steady = TrendTracker(lag=1.5, overlap=2.0, nominal={"c1": 1500.0}, q_rate_change=0.0)
    _, _, rate1 = _track_errors(steady, truth, 7.5, 7.5, t, seed=6)
    # the steady model alone lags the start of the wear
    assert abs(rate1[t >= 75.0][0] + 7.5) > abs(late[0] + 7.5)


@pytest.mark.parametrize("factor", [3.0, 0.5])
def test_calibration_scales_the_stated_variance_to_the_scatter(factor: float) -> None:
    """Window estimates whose stated stderr is 3 x (or half) their actual scatter: the
    calibrated scale approaches 1/9 (4), and the tracked error over the tracked stderr is
    about 1 (RMS within 0.5-1.6); without calibration the conservative stderr is far off."""
    t = np.arange(3.0, 200.0, 1.5)

    def truth(x: float) -> float:
        return 1500.0 - 2.0 * max(0.0, x - 50.0)

    tr = TrendTracker(lag=1.5, overlap=1.0, nominal={"c1": 1500.0})
    e, se, _ = _track_errors(tr, truth, 7.5, 7.5 * factor, t, seed=7)
    lam = tr.scale("c1")
    assert 0.5 / factor ** 2 < lam < 2.0 / factor ** 2
    z = float(np.sqrt(np.mean((e[t > 30.0] / se[t > 30.0]) ** 2)))
    assert 0.5 < z < 1.6
    if factor < 1.0:
        return
    raw = TrendTracker(lag=1.5, overlap=1.0, nominal={"c1": 1500.0}, calibrate=False)
    e0, se0, _ = _track_errors(raw, truth, 7.5, 7.5 * factor, t, seed=7)
    z0 = float(np.sqrt(np.mean((e0[t > 30.0] / se0[t > 30.0]) ** 2)))
    assert abs(math.log(z0)) > abs(math.log(z)) + 0.3


def _kink_window_mean(t_end: float, window: float = 3.0) -> float:
    """Exact mean over ``[t_end - window, t_end]`` of a damper at 1500 N s/m that starts
    losing 1.25 %/s of it at 20 s (the README demo's wear): what a constant-parameter window
    describes."""
    def area(x: float) -> float:
        return max(0.0, x - 20.0) ** 2 / 2.0
    return 1500.0 * (1.0 - 0.0125 * (area(t_end) - area(t_end - window)) / window)


def _kink_errors(seed: int, **kw: float) -> np.ndarray:
    """Relative errors of the tracked value at each window end (3 s windows every 1.5 s)
    against the truth there, on the kinked wear with 0.2 % window noise (stated 0.5 %)."""
    rng = np.random.default_rng(seed)
    tr = TrendTracker(lag=1.5, overlap=2.0, nominal={"c1": 1500.0}, **kw)
    err = []
    for ti in np.arange(3.0, 60.01, 1.5):
        y = _kink_window_mean(float(ti)) + rng.normal(0.0, 3.0)
        out = tr.update(float(ti), {"c1": y}, {"c1": 7.5})["c1"]
        err.append(out["value"] / (1500.0 * (1.0 - 0.0125 * max(0.0, ti - 20.0))) - 1.0)
    return np.array(err)


def test_rate_restart_takes_up_a_starting_wear_within_two_windows() -> None:
    """A wear that starts at 20 s at 1.25 %/s: once the changing model takes over (24 s), the
    restart refolds the last two estimates with a fresh rate. Over 20 noise draws the tracked
    value's RMS error from 24 to 30 s is 0.5 % on average (the former tracker, without the
    restart: 1.1 %, and it fails the 0.7 % bound on every draw), never worse than without."""
    t = np.arange(3.0, 60.01, 1.5)
    late = (t >= 24.0) & (t <= 30.0)
    new, old = [], []
    for seed in range(20):
        e1 = _kink_errors(seed)
        e0 = _kink_errors(seed, restart_rate=0.0)
        new.append(float(np.sqrt(np.mean(e1[late] ** 2))))
        old.append(float(np.sqrt(np.mean(e0[late] ** 2))))
        assert new[-1] <= old[-1] + 1e-3
        assert float(np.sqrt(np.mean(e1 ** 2))) <= float(np.sqrt(np.mean(e0 ** 2))) + 1e-3
    assert float(np.mean(new)) < 0.007
    assert min(old) > 0.007
    assert sum(n < 0.5 * o for n, o in zip(new, old)) >= 12


@pytest.mark.parametrize("stated", [7.5, 22.5])
def test_stable_part_with_the_restart_gets_no_forecast_and_no_alert(stated: float) -> None:
    """A stable damper (0.5 % window noise, stated honestly or 3 x too wide) over 300 s and
    ten noise draws: no forecast, no alert, the tracked value within 1 % of the truth."""
    for seed in range(10):
        rng = np.random.default_rng(100 + seed)
        tr = TrendTracker(lag=1.5, overlap=2.0, nominal={"c1": 1500.0})
        eng = _engine()
        alerts = AlertEngine(AlertConfig({"c1": 1500.0}), "quarter2", units={"c1": "N s/m"})
        for t in np.arange(3.0, 300.0, 1.5):
            out = tr.update(float(t), {"c1": 1500.0 + rng.normal(0.0, 7.5)}, {"c1": stated})
            eng.update(tr.trends(float(t)))
            alerts.update(float(t), {"c1": out["c1"]["value"]}, {"c1": out["c1"]["stderr"]})
            if t > 30.0:
                assert abs(out["c1"]["value"] - 1500.0) < 15.0
        assert eng.emitted == [] and alerts.emitted == []


def _forecasts_with_outlying_pairs(**kw: float | bool) -> int:
    """Forecasts on a stable damper (0.5 % window noise) whose estimates dip by 2 % and
    3 % in two consecutive windows every 37.5 s (a transient, not a wear), ten draws."""
    n = 0
    for seed in range(10):
        rng = np.random.default_rng(100 + seed)
        tr = TrendTracker(lag=1.5, overlap=2.0, nominal={"c1": 1500.0}, **kw)
        eng = _engine()
        for i, t in enumerate(np.arange(3.0, 300.0, 1.5)):
            dip = {23: -30.0, 24: -45.0}.get(i % 25, 0.0)
            tr.update(float(t), {"c1": 1500.0 + dip + rng.normal(0.0, 7.5)}, {"c1": 7.5})
            eng.update(tr.trends(float(t)))
        n += len(eng.emitted)
    return n


def test_two_outlying_windows_restart_the_rate_but_announce_no_forecast() -> None:
    """Two outlying windows look like the start of a wear to the restart; the restarted
    trend reports no data span for two estimates, by when the next windows have taken the
    rate back: no forecast. Announcing at once (``restart_hold=0``) forecasts a crossing
    that never comes (without the innovations' widening of the variance, which alone keeps
    some of those away); the former tracker (no restart) announces none either."""
    assert _forecasts_with_outlying_pairs() == 0
    at_once = _forecasts_with_outlying_pairs(restart_hold=0, innov_scale=False)
    assert at_once >= 3
    assert 0 < _forecasts_with_outlying_pairs(restart_hold=0) <= at_once
    assert _forecasts_with_outlying_pairs(restart_rate=0.0) == 0


def _kinked_track(seed: int, **kw: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tracked value, its stderr and the truth at each window end: a damper losing 1 %/s of
    1500 N s/m between 30 and 55 s, honest window estimates of its end value (7.5 N s/m)."""
    def truth(x: float) -> float:
        return 1500.0 - 15.0 * min(max(0.0, x - 30.0), 25.0)

    rng = np.random.default_rng(seed)
    tr = TrendTracker(nominal={"c1": 1500.0}, **kw)
    v, s, tv = [], [], []
    for ti in np.arange(1.5, 90.0, 1.5):
        out = tr.update(float(ti), {"c1": truth(float(ti)) + rng.normal(0.0, 7.5)},
                        {"c1": 7.5})["c1"]
        v.append(out["value"])
        s.append(out["stderr"])
        tv.append(truth(float(ti)))
    return np.array(v), np.array(s), np.array(tv)


def test_innovations_widen_the_stderr_at_a_kink_without_moving_the_value() -> None:
    """Where a wear starts or stops the track lags for a few windows and its error outgrows
    its stderr; the one-step innovations see it and widen the tracked variance for those
    windows: error/stderr nearer 1, the largest excursion smaller, the value itself the same."""
    z_on, z_off, worst_on, worst_off = [], [], [], []
    for seed in range(5):
        v1, s1, tv = _kinked_track(seed)
        v0, s0, _ = _kinked_track(seed, innov_scale=False)
        np.testing.assert_allclose(v1, v0, rtol=0, atol=1e-9)
        assert np.all(s1 >= s0 - 1e-12)
        z_on.append((v1 - tv) / s1)
        z_off.append((v0 - tv) / s0)
        worst_on.append(np.abs(z_on[-1]).max())
        worst_off.append(np.abs(z_off[-1]).max())
    rms_on = float(np.sqrt(np.mean(np.concatenate(z_on) ** 2)))
    rms_off = float(np.sqrt(np.mean(np.concatenate(z_off) ** 2)))
    assert rms_off > 1.05 and 0.7 < rms_on < rms_off - 0.1
    assert max(worst_on) < max(worst_off) - 0.5
    # a filter's own outputs (not calibrated) keep their variances
    tr = TrendTracker(nominal={"c1": 1500.0}, calibrate=False)
    for ti in (1.5, 3.0, 4.5):
        tr.update(ti, {"c1": 1500.0 + 100.0 * ti}, {"c1": 7.5})
    assert tr.honesty("c1") == 1.0
