"""Trend tracking, alerts from the tracker, and forecasts of the limit crossing."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from estimator.alerts import (AlertStore, ForecastEngine, ForecastEvent, Trend, crossing,
                              linear_trend)
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
    # wearing at 0.67 %/s (to 1305 N s/m): a forecast; then the damper is replaced: withdrawn
    v = 1500.0
    for t in np.arange(200.0, 219.0, 1.5):
        v -= 10.0 * 1.5
        tr.update(float(t), {"c1": v + rng.normal(0.0, 7.5)}, {"c1": 7.5})
        eng.update(tr.trends(float(t)))
    kinds = [e.kind for e in eng.emitted]
    assert kinds and kinds[0] == "forecast"
    first = eng.emitted[0]
    assert first.crossing_t is not None and first.crossing_t > first.t
    assert "will cross 70 % of nominal" in first.message
    for t in np.arange(219.0, 320.0, 1.5):
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


def test_estimator_does_not_import_the_cli() -> None:
    code = ("import sys; import estimator.stream.pipeline, estimator.stream.compare, "
            "estimator.output_only, estimator.ekf.stream; "
            "bad = [m for m in sys.modules if m.startswith('suspid.cli')]; print(bad)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"
