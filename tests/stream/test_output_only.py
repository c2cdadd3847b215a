"""Output-only mode: body mode from a body accelerometer (synthetic truth, and the real CANedge drive)."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from estimator.output_only import OutputOnlyEstimator, fit_ar, fit_carma
from suspid.models.modes import modes
from estimator.stream.drivers import run_arrays
from estimator.stream.wear_streams import damper_wear


@pytest.fixture(scope="module")
def accel_stream(quarter2):
    # 10 minutes at 100 Hz; the damper wears from 300 s on to 40 % of nominal
    return damper_wear(quarter2, duration=600.0, fs=100.0, wear_start=300.0, c_end_fraction=0.4,
                       channels=("x1_ddot",), seed=8, chunk_s=0.5)


def test_body_mode_found_on_synthetic_acceleration(quarter2, accel_stream) -> None:
    s = accel_stream
    body = modes(quarter2, s.nominal)[0]
    est = OutputOnlyEstimator("x1_ddot")
    res = []
    run_arrays(s.t, {"x1_ddot": s.data["x1_ddot"]}, 60.0, 30.0, lambda t, d: res.append(est.process(t, d)))
    lines = [r.event.to_json() for r in res]
    assert all(l["type"] == "estimate" for l in lines) and len(lines) == 19
    healthy = [l for l in lines if l["t"] <= 300.0]
    f = np.median([l["f_hz"] for l in healthy])
    z = np.median([l["zeta"] for l in healthy])
    assert f == pytest.approx(body.f_n, rel=0.08)
    assert z == pytest.approx(body.zeta, abs=0.08)
    # the wearing damper shows as a falling damping ratio
    worn = [l for l in lines if l["t_start"] >= 480.0]
    assert np.median([l["zeta"] for l in worn]) < z - 0.05
    assert all(l["stderr"]["f_body"] > 0 for l in lines)


def test_ar_method_finds_the_same_band(accel_stream) -> None:
    s = accel_stream
    sl = s.t < 120
    m = fit_ar(s.data["x1_ddot"][sl], 100.0)
    c = fit_carma(s.data["x1_ddot"][sl], 100.0)
    assert 0.8 < m.f_hz < 2.0 and 0.8 < c.f_hz < 2.0


def test_parked_vehicle_is_skipped() -> None:
    t = np.arange(0, 60, 0.01)
    est = OutputOnlyEstimator("x1_ddot")
    r = est.process(t, {"x1_ddot": 9.81 + np.random.default_rng(0).normal(0, 0.005, t.size)})
    line = r.event.to_json()
    assert line["type"] == "skip" and "too little excitation" in line["reason"]


@pytest.mark.slow
def test_real_canedge_drive_body_bounce(realdata) -> None:
    d = realdata / "canedge-imu"
    mf4 = sorted(d.glob("*.MF4"))[0]
    r = subprocess.run([sys.executable, "-m", "suspid", "monitor", "--model", "quarter2",
                        "--output-only", "--input", str(mf4), "--dbc", str(d / "canmod-gps.dbc"),
                        "--map", "x1_ddot=gnss_imu.AccelerationX", "--jsonl"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    out = [json.loads(l) for l in r.stdout.splitlines()]
    est = [o for o in out if o["type"] == "estimate"]
    assert len(est) >= 15                       # 600 s in 60 s windows every 30 s
    f = np.array([o["f_hz"] for o in est])
    z = np.array([o["zeta"] for o in est])
    # the body bounce of this car: per window 1.0-1.8 Hz, median near 1.4 Hz (docs/monitoring.md)
    assert 1.2 < np.median(f) < 1.6
    assert np.all((f > 0.8) & (f < 2.0))
    assert 0.15 < np.median(z) < 0.45
    assert out[-1]["frames"]["rejected"]["unknown_id"] > 0   # foreign traffic counted, not fatal
