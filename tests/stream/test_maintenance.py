"""Predictive maintenance on held-out streams: the sliding window against the fair EKF.

The stiff quarter car (Table 1) at 2 % noise is the stream on which the former EKF (holding
c2, k2 at the model's defaults) tracked a wrong model and the window estimator skipped most
windows; the half car checks the same on a 4-DOF model with two roads, the full car on a 7-DOF
model with four.
"""
from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from estimator.identify import Parameters
from estimator.stream.compare import compare
from estimator.stream.config import default_config
from estimator.stream.wear_streams import damper_wear
from estimator.stream.window import SlidingWindowIdentifier
from suspid.io.csvio import write_measurement
from suspid.models import get_model
from tests.conftest import write_config
from tools.bench_maintenance import FULL7_KNOWN, Case, full7_stream

from .conftest import TABLE1


@pytest.fixture(scope="module")
def stiff(stiff_wear_stream):
    s = stiff_wear_stream
    fix = {"m1": TABLE1["m1"], "m2": TABLE1["m2"]}
    nominal = {k: v for k, v in TABLE1.items() if k not in fix}
    out, _ = compare(get_model("quarter2"), s.t, s.data, s.truth, fix=fix, nominal=nominal)
    return out


@pytest.mark.slow
def test_window_estimator_beats_the_fair_ekf_on_the_stiff_stream(stiff) -> None:
    nm, ekf = stiff["nm"], stiff["ekf_result"]
    # the EKF estimates what the window estimates and holds nothing
    assert ekf["augmented"] == ["c1", "k1", "c2", "k2"] and ekf["held"] == {}
    assert nm["skipped"] == 0 and nm["estimates"] == ekf["estimates"]
    c1n, c1e = nm["params"]["c1"], ekf["params"]["c1"]
    assert c1n["crossing_t"] == pytest.approx(84.0, abs=0.01)
    assert c1n["rmse_pct"] <= c1e["rmse_pct"] and c1n["rmse_pct"] < 3.0
    assert c1n["alert_delay_s"] is not None and c1e["alert_delay_s"] is not None
    assert c1n["alert_delay_s"] <= c1e["alert_delay_s"]
    for side in (nm, ekf):
        assert all(p.get("false_alarms", 0) == 0 for p in side["params"].values())
        assert all(p["forecasts"] == 0 for k, p in side["params"].items() if k != "c1")
    assert nm["cpu_us_per_sample"] < ekf["cpu_us_per_sample"]


def test_first_forecast_ten_seconds_ahead_with_the_crossing_inside(stiff) -> None:
    c1 = stiff["nm"]["params"]["c1"]
    assert c1["forecast_lead_s"] >= 10.0
    assert c1["forecast_first_contains"]


@pytest.mark.slow
def test_monitor_cli_forecast_line_and_text(stiff_wear_stream, tmp_path) -> None:
    s = stiff_wear_stream
    csv = tmp_path / "stiff.csv"
    sl = s.t <= 90.0
    write_measurement(csv, s.t[sl], {k: v[sl] for k, v in s.data.items()})
    base = [sys.executable, "-m", "suspid", "monitor", "--model", "quarter2", "--input", str(csv),
            "--fix", "m1=275", "--fix", "m2=27", "--nominal", "c1=1120", "--nominal", "k1=150000",
            "--nominal", "c2=3100", "--nominal", "k2=310000", "--no-inspection"]
    r = subprocess.run(base + ["--jsonl"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    out = [json.loads(l) for l in r.stdout.splitlines()]
    fc = [d for d in out if d["type"] == "forecast"]
    assert fc and fc[0]["parameter"] == "c1"
    keys = {"t", "parameter", "value", "rate", "limit", "crossing_t", "crossing_t_low",
            "crossing_t_high", "message"}
    assert keys <= set(fc[0])
    assert fc[0]["limit"] == pytest.approx(784.0)
    assert fc[0]["crossing_t_low"] <= 84.0 <= fc[0]["crossing_t_high"]
    assert fc[0]["t"] <= 74.0
    est = [d for d in out if d["type"] == "estimate"]
    assert all(set(d["track"]["c1"]) == {"value", "stderr", "rate", "rate_stderr"} for d in est)
    txt = subprocess.run(base, capture_output=True, text=True, timeout=300)
    assert txt.returncode == 0
    assert any(l.startswith(f"t={fc[0]['t']:.2f} s FORECAST: c1 = ") for l in txt.stdout.splitlines())


@pytest.fixture(scope="module")
def half4_run(half4_wear_stream):
    s = half4_wear_stream
    fix = {k: s.nominal[k] for k in ("m", "I", "m1", "m2", "a1", "a2")}
    nominal = {k: v for k, v in s.nominal.items() if k not in fix}
    out, _ = compare(get_model("half4"), s.t, s.data, s.truth, fix=fix, nominal=nominal)
    return out


@pytest.mark.slow
def test_half4_monitor_ekf_compare_and_forecast(half4_run) -> None:
    nm, ekf = half4_run["nm"], half4_run["ekf_result"]
    assert ekf["augmented"] == ["c1", "c2", "k1", "k2", "k3", "k4"] and ekf["held"] == {}
    c1n, c1e = nm["params"]["c1"], ekf["params"]["c1"]
    assert c1n["crossing_t"] == pytest.approx(50.0, abs=0.01)
    assert c1n["rmse_pct"] < 3.0 and c1n["rmse_pct"] <= c1e["rmse_pct"]
    assert 0.0 <= c1n["alert_delay_s"] <= 10.0 and c1n["alert_delay_s"] <= c1e["alert_delay_s"]
    for side in (nm, ekf):
        for k, p in side["params"].items():
            assert p.get("false_alarms", 0) == 0
            if k != "c1":
                assert p["alerts"] == [] and p["forecasts"] == 0 and p["rmse_pct"] < 2.0
    assert c1n["forecast_lead_s"] >= 10.0 and c1n["forecast_first_contains"]


@pytest.mark.slow
def test_half4_held_mass_is_reported(half4_wear_stream, tmp_path) -> None:
    """A free mass cannot be in the EKF's state: it is held, and every estimate says so."""
    s = half4_wear_stream
    csv = tmp_path / "h4.csv"
    sl = s.t <= 20.0
    write_measurement(csv, s.t[sl], {k: v[sl] for k, v in s.data.items()})
    r = subprocess.run([sys.executable, "-m", "suspid", "monitor", "--model", "half4", "--input",
                        str(csv), "--fix", "m=1200", "--fix", "I=1500", "--fix", "m2=40",
                        "--fix", "a1=1.2", "--fix", "a2=1.4", "--baseline", "ekf", "--jsonl"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    est = [json.loads(l) for l in r.stdout.splitlines() if '"estimate"' in l]
    assert est and all("m1" in d["held"] and "mass" in d["held"]["m1"] for d in est)
    assert "m1" not in est[0]["stderr"] and "c1" in est[0]["stderr"]


@pytest.mark.slow
def test_full7_monitor_and_fair_ekf_on_a_stable_car(tmp_path) -> None:
    """The full car: both estimators run on the same stream, estimate the same twelve dampers,
    springs and tyres, stay near the truth and neither alerts nor forecasts."""
    csv = tmp_path / "f7.csv"
    sim = subprocess.run([sys.executable, "-m", "suspid", "simulate", "--model", "full7",
                          "--scenario", "iso8608", "--duration", "12", "--fs", "250", "--noise",
                          "0.01", "--seed", "2", "--out", str(csv)],
                         capture_output=True, text=True, timeout=300)
    assert sim.returncode == 0, sim.stderr
    truth = get_model("full7").defaults()
    known = ("m", "Ix", "Iy", "m1", "m2", "m3", "m4", "a1", "a2", "w1", "w2")
    fix = [a for k in known for a in ("--fix", f"{k}={truth[k]}")]
    outs = {}
    for side in ("nm", "ekf"):
        extra = ["--baseline", "ekf"] if side == "ekf" else []
        r = subprocess.run([sys.executable, "-m", "suspid", "monitor", "--model", "full7",
                            "--input", str(csv), *fix, *extra, "--jsonl", "--no-inspection"],
                           capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, r.stderr
        outs[side] = [json.loads(l) for l in r.stdout.splitlines()]
    free = {k for k in truth if k not in known}
    for side, out in outs.items():
        est = [d for d in out if d["type"] == "estimate"]
        assert len(est) >= 4 and set(est[-1]["stderr"]) == free, side
        for k in free:
            assert est[-1]["params"][k] == pytest.approx(truth[k], rel=0.03), (side, k)
        assert not [d for d in out if d["type"] in ("alert", "forecast")], side
    assert outs["ekf"][-1]["held"] == {} and len(outs["ekf"][-1]["augmented"]) == 12


@pytest.mark.slow
def test_demo_stream_forecast_ten_seconds_ahead_and_alert_no_later_than_the_ekf() -> None:
    """``suspid compare``'s default stream (quantization only, c1 -50 % over 130 s, crossing
    at 98 s): the window's stated stderr is mostly its sigma_floor; with the tracker's
    calibrated variances the first forecast comes >= 10 s ahead with the crossing inside
    its interval, the alert no later than the EKF's, the tracked c1 no less accurate."""
    m = get_model("quarter2")
    s = damper_wear(m, duration=150.0, fs=500.0, seed=0, c_end_fraction=0.5)
    fix = {k: s.nominal[k] for k in ("m1", "m2", "c2", "k2")}
    nominal = {k: s.nominal[k] for k in ("c1", "k1")}
    out, _ = compare(m, s.t, s.data, s.truth, fix=fix, nominal=nominal)
    c1n, c1e = out["nm"]["params"]["c1"], out["ekf_result"]["params"]["c1"]
    assert c1n["crossing_t"] == pytest.approx(98.0, abs=0.01)
    assert c1n["forecast_lead_s"] >= 10.0 and c1n["forecast_first_contains"]
    assert c1n["alert_delay_s"] is not None and c1e["alert_delay_s"] is not None
    assert 0.0 <= c1n["alert_delay_s"] <= c1e["alert_delay_s"]
    assert c1n["rmse_pct"] <= c1e["rmse_pct"]
    # the stderr the alerts use is neither far below nor far above the actual error
    assert 0.3 < c1n["error_over_stderr_rms"] < 1.5
    for side in (out["nm"], out["ekf_result"]):
        assert all(p.get("false_alarms", 0) == 0 for p in side["params"].values())
        assert side["params"]["k1"]["forecasts"] == 0


@pytest.mark.slow
def test_stable_stream_tracked_no_worse_than_the_ekf() -> None:
    """A soft quarter car at 2 % noise without wear: the tracker's steady model averages the
    windows (c1 no less accurate than the EKF's state), and neither side alerts or
    forecasts."""
    m = get_model("quarter2")
    soft = {"m1": 300.0, "c1": 1500.0, "k1": 20000.0, "m2": 40.0, "c2": 300.0, "k2": 200000.0}
    kw = dict(duration=90.0, fs=500.0, params=soft, c_end_fraction=1.0, wear_start=30.0,
              wear_end=80.0, seed=11)
    clean = damper_wear(m, noise={c: 0.0 for c in ("x1", "x2", "x1_ddot", "r", "r_dot")},
                        quantize=False, **kw)
    s = damper_wear(m, noise={c: 0.02 * float(np.std(v)) for c, v in clean.data.items()}, **kw)
    fix = {"m1": 300.0, "m2": 40.0}
    nominal = {k: v for k, v in soft.items() if k not in fix}
    out, _ = compare(m, s.t, s.data, s.truth, fix=fix, nominal=nominal)
    assert out["nm"]["params"]["c1"]["rmse_pct"] <= out["ekf_result"]["params"]["c1"]["rmse_pct"]
    for side in (out["nm"], out["ekf_result"]):
        for p in side["params"].values():
            assert p["alerts"] == [] and p["forecasts"] == 0


@pytest.mark.slow
def test_monitor_cli_window_drift_refers_estimates_to_the_window_end(tmp_path) -> None:
    """The window's linear drift (by default on the struts' free dampers and springs, here
    c1 and k1; ``[window] drift = []`` turns it off) on a quantization-only ramp (c1
    -2 %/s): the window estimates describe the window end (the constant windows lag it by
    half a window); a parameter that is not free is a one-line usage error."""
    m = get_model("quarter2")
    s = damper_wear(m, duration=20.0, fs=500.0, wear_start=0.0, wear_end=20.0,
                    c_end_fraction=0.6, seed=7)
    csv = tmp_path / "ramp.csv"
    write_measurement(csv, s.t, s.data)
    fix = [a for k in ("m1", "m2", "c2", "k2") for a in ("--fix", f"{k}={s.nominal[k]}")]
    base = [sys.executable, "-m", "suspid", "monitor", "--model", "quarter2", "--input", str(csv),
            *fix, "--nominal", f"c1={s.nominal['c1']}", "--no-inspection", "--jsonl"]
    err = {}
    for drift, extra in ((False, ["--config", write_config(tmp_path, "[window]\ndrift = []\n",
                                                           "off.toml")]), (True, [])):
        r = subprocess.run(base + extra, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        est = [d for d in map(json.loads, r.stdout.splitlines()) if d["type"] == "estimate"]
        assert len(est) >= 10
        e = [d["params"]["c1"] / float(np.interp(d["t"], s.t, s.truth["c1"])) - 1.0
             for d in est[3:]]
        err[drift] = float(np.sqrt(np.mean(np.square(e))))
        # the tracked value (window end) takes no lag for a drift window's estimate
        e = [d["track"]["c1"]["value"] / float(np.interp(d["t"], s.t, s.truth["c1"])) - 1.0
             for d in est[5:]]
        err[("track", drift)] = float(np.sqrt(np.mean(np.square(e))))
    assert err[False] > 0.01  # the half-window lag at 2 %/s of nominal
    assert err[True] < 0.4 * err[False]
    assert err[("track", True)] < 0.5 * err[False]
    r = subprocess.run(base + ["--config", write_config(tmp_path, '[window]\ndrift = ["c2"]\n',
                                                        "c2.toml")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines()[-1].startswith("error: drift: c2 not among the free")


@pytest.mark.slow
def test_full7_wearing_stream_through_compare() -> None:
    """The full car losing front-left damping (c1 -50 % between 10 and 50 s, crossing 70 %
    at 34 s; 250 Hz, 1 % noise on the seven positions and four roads): both sides estimate the
    same twelve dampers, springs and tyres (the EKF holds none), neither alerts falsely nor on
    a part that does not wear; the window alerts on c1 within 10 s of the crossing, forecasts
    it >= 10 s ahead with the crossing inside the 90 % interval and tracks it no less
    accurately than the EKF (measured: c1 RMSE 0.79 / 2.50 %, alert 3.5 / 5.0 s, first
    forecast 16.0 s ahead, the other parts' RMSE < 0.9 % on both sides)."""
    case = Case("full7", "full car", None, 0.01, 55.0, 10.0, 50.0, 0.5, 6, model="full7")
    s = full7_stream(case)
    m = get_model("full7")
    fix = {k: s.nominal[k] for k in FULL7_KNOWN}
    nominal = {k: v for k, v in s.nominal.items() if k not in fix}
    out, _ = compare(m, s.t, s.data, s.truth, fix=fix, nominal=nominal)
    nm, ekf = out["nm"], out["ekf_result"]
    free = set(nominal)
    assert len(free) == 12 and set(out["ekf"]["augmented"]) == free and out["ekf"]["held"] == {}
    assert set(nm["params"]) == set(ekf["params"]) == free
    assert nm["skipped"] == 0 and nm["estimates"] == ekf["estimates"] > 0
    c1n, c1e = nm["params"]["c1"], ekf["params"]["c1"]
    assert c1n["crossing_t"] == pytest.approx(34.0, abs=0.01)
    for side in (nm, ekf):
        for k, p in side["params"].items():
            assert p.get("false_alarms", 0) == 0, k
            if k != "c1":
                assert p["alerts"] == [] and p["forecasts"] == 0 and p["rmse_pct"] < 2.0, k
    assert c1n["alert_delay_s"] is not None and 0.0 <= c1n["alert_delay_s"] <= 10.0
    assert c1n["forecast_lead_s"] >= 10.0 and c1n["forecast_first_contains"]
    # the interval holds the crossing with room (0.96 s; 0.011 s before the tracker widened
    # its stated variances by the innovations), and the stated stderr is near the error
    assert c1n["forecast_first_margin_s"] >= 0.5
    assert c1n["error_over_stderr_rms"] < 1.3
    assert c1n["rmse_pct"] < 2.0 and c1n["rmse_pct"] <= c1e["rmse_pct"]


def test_full7_first_window_one_nelder_mead_run_then_gauss_newton() -> None:
    """Twelve free parameters: the cold first window runs Nelder-Mead once (no restart) and
    the Gauss-Newton steps finish it, in under 70 % of the evaluations of four restarts
    without them (measured 395 against 642 here, 400 against 878 on the benchmark stream)
    and at a cost no higher; the steps themselves lower the cost of Nelder-Mead's best vertex."""
    case = Case("full7", "full car", None, 0.01, 8.0, 10.0, 50.0, 0.5, 6, model="full7")
    s = full7_stream(case)
    m = get_model("full7")
    fix = {k: s.nominal[k] for k in FULL7_KNOWN}
    free = [k for k in s.nominal if k not in fix]
    params = Parameters.for_model(m, fix=fix, init={k: s.nominal[k] for k in free})
    cfg = default_config(m, s.nominal, 250.0, len(free))
    assert cfg.first_restarts == 0 and cfg.gauss_newton_step
    n = int(round(cfg.window_s * 250.0)) + 1
    window = {c: v[:n] for c, v in s.data.items()}
    out = {}
    for label, opts in (("new", {}), ("nm", {"gauss_newton_step": False}),
                        ("old", {"gauss_newton_step": False, "first_restarts": 4})):
        ident = SlidingWindowIdentifier(m, params, replace(cfg, **opts), list(m.coords))
        out[label] = ident.process(s.t[:n], window)
        assert not out[label].skipped and out[label].converged
    assert out["new"].nfev <= out["nm"].nfev + len(free) + cfg.gauss_newton_steps
    assert out["new"].nfev < 0.7 * out["old"].nfev
    assert out["new"].cost < out["nm"].cost
    assert out["new"].cost <= out["old"].cost * (1 + 1e-6)
