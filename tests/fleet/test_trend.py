"""Trends, alerts and forecasts: robust to a bad drive, intervals that hold their level,
and on the synthetic fleet the truth (wear rate, crossing date) inside the answers."""
from __future__ import annotations

from typing import Any

import numpy as np

from estimator.alerts.forecast import inverse_2x2, linear_trend, wls_line
from estimator.fleet.trend import DAY_S, forecast_crossing, robust_trend
from tests.fleet.conftest import Fleet

T0 = 1.79e9


def _drives(seed: int, n: int = 12, rate: float = -5.0, scatter: float = 15.0
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    days = np.sort(rng.uniform(0, 60, n))
    return T0 + days * DAY_S, 1500 + rate * days + rng.normal(0, scatter, n), np.full(n, 3.0)


def test_one_bad_drive_does_not_move_the_trend() -> None:
    t, v, s = _drives(3)
    clean = robust_trend(t, v, s)
    bad = v.copy()
    bad[-2] *= 0.5                     # a mis-scaled sensor: half the damping, small stderr
    robust = robust_trend(t, bad, s)
    assert robust is not None and clean is not None
    assert robust.outliers == (10,)
    assert abs(robust.rate - clean.rate) * DAY_S < 0.5 * clean.rate_stderr * DAY_S + 1e-9
    x = (t - t.max()) / DAY_S
    ols = np.polyfit(x, bad, 1)[0]     # ordinary least squares is dragged away
    assert abs(ols - clean.rate * DAY_S) > 5 * clean.rate_stderr * DAY_S
    assert abs(robust.rate * DAY_S - (-5.0)) < 3 * robust.rate_stderr * DAY_S


def test_forecast_interval_holds_its_level() -> None:
    """Over 300 synthetic vehicles (12 drives, scatter 5x the per-drive stderr, half with
    one bad drive) the 90 % interval contains the true crossing (day 90) 85-95 % of the
    time, and the slope's stderr is honest: |error| / stderr exceeds the t(10) 90 %
    quantile (1.812) in about 10 % of them."""
    hits, z = 0, []
    for seed in range(300):
        t, v, s = _drives(seed)
        if seed % 2:
            v[5] *= 0.5
        tr = robust_trend(t, v, s)
        fc = forecast_crossing(tr, 1050.0, 0.90)
        assert tr is not None and fc is not None
        hits += fc.crossing_t_low <= T0 + 90 * DAY_S <= fc.crossing_t_high
        z.append((tr.rate * DAY_S + 5.0) / (tr.rate_stderr * DAY_S))
    assert 0.84 <= hits / 300 <= 0.96, hits
    assert 0.05 <= np.mean(np.abs(z) > 1.812) <= 0.16


def test_no_forecast_without_a_falling_trend() -> None:
    t, v, s = _drives(5, rate=0.0)
    assert forecast_crossing(robust_trend(t, v, s), 1050.0) is None
    t, v, s = _drives(5, rate=+2.0)
    assert forecast_crossing(robust_trend(t, v, s), 1050.0) is None
    assert robust_trend(t[:1], v[:1], s[:1]) is None
    two = robust_trend(t[:2], v[:2], s[:2])
    assert two is not None and np.isnan(two.rate_stderr) and forecast_crossing(two, 1050.0) is None


def test_wearing_fleet_alert_forecast_and_rank(fleet: Fleet, inprocess: dict[str, Any]) -> None:
    v = {x["vehicle"]: x for x in inprocess["vehicles"]}
    worn, wear, ok = v["VAN-WORN"], v["VAN-WEAR"], v["VAN-OK"]
    # the worn damper is below 70 % in its last two drives: the monitor's rule alerts
    assert worn["alerts"] == ["c1"] and wear["alerts"] == [] and ok["alerts"] == []
    assert worn["alert_details"][0]["bound"] < worn["alert_details"][0]["limit"] == 1050.0
    # the wearing one: trend at the true rate, crossing forecast around the true date
    true_rate = -1500.0 * fleet.vehicle("VAN-WEAR").c1_rate
    tr = wear["trend"]["c1"]
    assert abs(tr["rate_per_day"] - true_rate) < 3 * tr["stderr"]
    assert abs(tr["rate_per_day"] - true_rate) < 0.05 * abs(true_rate)
    fc = wear["forecast"]["c1"]
    true_t = fleet.spec.crossing_t(fleet.vehicle("VAN-WEAR"), "c1", 0.3)
    assert fc["crossing_t_low"] <= true_t <= fc["crossing_t_high"]
    assert fc["crossing_t_low"] < fc["crossing_t"] < fc["crossing_t_high"]
    assert "c1" not in ok["forecast"]
    for k in ("k1", "c2", "k2"):      # no wear there: rates consistent with zero
        assert abs(ok["trend"][k]["rate_per_day"]) < 4 * ok["trend"][k]["stderr"]
    assert [x["vehicle"] for x in inprocess["vehicles"]] == ["VAN-WORN", "VAN-WEAR", "VAN-OK"]
    assert [x["rank"] for x in inprocess["vehicles"]] == [1, 2, 3]


def test_closed_form_line_equals_numpy_least_squares() -> None:
    """The one closed-form weighted line (behind the fleet's and the monitor's trends)
    against numpy's least squares on the whitened system, the oracle."""
    rng = np.random.default_rng(11)
    x = np.sort(rng.uniform(-60, 0, 15))
    v = 1500 - 4.0 * x + rng.normal(0, 20, 15)
    w = 1.0 / rng.uniform(5, 30, 15) ** 2
    beta, M = wls_line(x, v, w)
    X = np.column_stack([np.ones_like(x), x]) * np.sqrt(w)[:, None]
    ref = np.linalg.lstsq(X, v * np.sqrt(w), rcond=None)[0]
    np.testing.assert_allclose(beta, ref, rtol=1e-10)
    np.testing.assert_allclose(inverse_2x2(M), np.linalg.inv(X.T @ X), rtol=1e-10)
    tr = linear_trend(x, v, 1.0 / np.sqrt(w))
    assert tr.n == 15 and tr.t == x[-1]
    assert abs(tr.rate - ref[1]) < 1e-9 * abs(ref[1])
