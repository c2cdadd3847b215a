"""The damper-wear stream: a damper falling through 70 % of nominal is flagged a few seconds after
the crossing and never before; c1 is tracked within 5 % RMS; the EKF's track is reported beside."""
from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.stream.compare import compare
from estimator.stream.config import default_config

#: "within a few seconds": half a window of lag + the confidence margin + one step of
#: persistence is about 5-6 s for the default 3 s windows on this drift (0.42 %/s)
MAX_DELAY_S = 8.0


@pytest.fixture(scope="module")
def runs(wear_stream, quarter2):
    s = wear_stream
    fix = {k: s.nominal[k] for k in ("m1", "m2", "c2", "k2")}
    nominal = {k: v for k, v in s.nominal.items() if k not in fix}
    out, (rec_nm, rec_ekf) = compare(quarter2, s.t, s.data, s.truth, fix=fix, nominal=nominal)
    cfg = default_config(quarter2, s.nominal, 500.0, 2)
    return rec_nm, out["nm"], rec_ekf, out["ekf_result"], cfg


@pytest.mark.slow
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
    # the forecast came well before the crossing and its 90 % interval holds it
    assert c1["forecast_lead_s"] >= 10.0, c1
    assert c1["forecast_first_contains"], c1
    assert m_nm["params"]["k1"]["forecasts"] == 0


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
    # the fair EKF estimates what the window estimates, holds nothing silently
    assert m_ekf["augmented"] == ["c1", "k1"] and m_ekf["held"] == {}
    assert math.isfinite(m_ekf["nis"])
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
