"""Issue 5 must-show: a damper falling through 70 % of nominal is flagged a few seconds after
the crossing and never before; c1 is tracked within 5 % RMS; the EKF's track is reported beside."""
from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.alerts import AlertConfig
from estimator.ekf import EKFWindowEstimator
from estimator.identify import Parameters
from estimator.stream.compare import metrics, run_one
from estimator.stream.config import default_config
from estimator.stream.monitor import NMWindowEstimator

#: "within a few seconds": half a window of lag + the confidence margin + one step of
#: persistence is about 5-6 s for the default 3 s windows on this drift (0.42 %/s)
MAX_DELAY_S = 8.0


@pytest.fixture(scope="module")
def runs(wear_stream, quarter2):
    s = wear_stream
    fix = {k: s.nominal[k] for k in ("m1", "m2", "c2", "k2")}
    params = Parameters.for_model(quarter2, fix=fix)
    cfg = default_config(quarter2, s.nominal, 500.0, len(params.free))
    nominal = {k: s.nominal[k] for k in params.free}
    acfg = AlertConfig(nominal, drop=0.3, persistence_s=cfg.step_s)
    nm = NMWindowEstimator(quarter2, params, cfg, ["x1", "x2", "x1_ddot"], inspection=False)
    rec_nm = run_one(nm, s.t, s.data, cfg.window_s, cfg.step_s, acfg, "quarter2")
    ekf = EKFWindowEstimator(quarter2, s.nominal, ["c1", "k1"], ["x1", "x2", "x1_ddot"], decimate=2)
    rec_ekf = run_one(ekf, s.t, s.data, cfg.window_s, cfg.step_s,
                      AlertConfig({"c1": nominal["c1"], "k1": nominal["k1"]}, persistence_s=cfg.step_s),
                      "quarter2")
    m_nm = metrics(rec_nm, s.t, s.truth, nominal, 0.3, s.t.size)
    m_ekf = metrics(rec_ekf, s.t, s.truth, {"c1": nominal["c1"], "k1": nominal["k1"]}, 0.3, s.t.size)
    return rec_nm, m_nm, rec_ekf, m_ekf, cfg


def test_first_c1_alert_after_crossing_within_a_few_seconds(runs, wear_stream) -> None:
    rec_nm, m_nm, *_ = runs
    crossing = wear_stream.crossing_time("c1", 0.7 * wear_stream.nominal["c1"])
    assert 63.0 < crossing < 65.0
    c1 = m_nm["params"]["c1"]
    assert c1["alerts"], "no c1 alert although c1 fell to 50 % of nominal"
    assert c1["false_alarms"] == 0
    assert all(t >= crossing for t in c1["alerts"])
    assert 0.0 <= c1["alert_delay_s"] <= MAX_DELAY_S, c1
    # one episode, one alert; k1 did not change and never alerts
    assert len(c1["alerts"]) == 1
    assert m_nm["params"]["k1"]["alerts"] == []


def test_c1_tracking_error_below_5_percent(runs) -> None:
    _, m_nm, _, m_ekf, _ = runs
    assert m_nm["estimates"] >= 60  # every 1.5 s from 3 s to 100 s
    assert m_nm["skipped"] == 0
    assert m_nm["params"]["c1"]["rmse_pct"] < 5.0
    assert m_nm["params"]["k1"]["rmse_pct"] < 5.0


def test_ekf_c1_track_reported_beside(runs, capsys) -> None:
    _, m_nm, rec_ekf, m_ekf, _ = runs
    ekf_c1 = m_ekf["params"]["c1"]
    assert math.isfinite(ekf_c1["rmse_pct"])
    # the EKF is a working baseline, not a straw man: it also tracks the wearing damper
    assert ekf_c1["rmse_pct"] < 10.0
    assert m_ekf["estimates"] == m_nm["estimates"]
    with capsys.disabled():
        print(f"\n  c1 tracking RMS error: NM windows {m_nm['params']['c1']['rmse_pct']:.2f} %, "
              f"EKF {ekf_c1['rmse_pct']:.2f} %; alert delay NM "
              f"{m_nm['params']['c1']['alert_delay_s']:.2f} s, EKF {ekf_c1['alert_delay_s']} s")


def test_estimates_carry_stderr_budget_and_window_end_time(runs) -> None:
    rec_nm, _, _, _, cfg = runs
    est = [l for l in rec_nm.lines if l["type"] == "estimate"]
    ends = np.array([l["t"] for l in est])
    # t is the data time at the window end: first end = window, then every step
    assert ends[0] == pytest.approx(cfg.window_s, abs=2e-3)
    assert np.allclose(np.diff(ends), cfg.step_s, atol=2e-3)
    for l in est:
        assert set(l["stderr"]) == {"c1", "k1"}
        assert all(v > 0 and math.isfinite(v) for v in l["stderr"].values())
        assert l["nfev"] <= l["budget"]
        assert l["t"] - l["t_start"] == pytest.approx(cfg.window_s, abs=2e-3)
    # warm starts are cheaper than the cold first window
    assert np.median([l["nfev"] for l in est[1:]]) < est[0]["nfev"]
