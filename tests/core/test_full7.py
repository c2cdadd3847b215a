"""The 7-DOF full car: its equations, an independent reduction to half4, its geometry,
roads, identification (accuracy and standard errors) and the command line end to end."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from estimator.identify import OutputErrorProblem, Parameters, fit
from suspid.excitation import make_scenario, measured_road
from suspid.io.csvio import Measurement, read_measurement
from suspid.models import GRAVITY, get_model
from suspid.simulate import simulate

FULL7 = get_model("full7")
P = FULL7.defaults()
FREE = [n for n in FULL7.param_names if n not in FULL7.known]


def _suspid(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "suspid", *args], capture_output=True, text=True,
                          timeout=600)


def test_equations_of_motion_term_by_term() -> None:
    """Newton-Euler for every body, written out corner by corner."""
    p = dict(P, c1=1700.0, c4=1500.0, k2=26000.0, kt3=190000.0, w2=1.6)
    rng = np.random.default_rng(7)
    s = rng.standard_normal(14) * 0.05
    r = rng.standard_normal(4) * 0.02
    acc = FULL7.rhs(0.0, s, np.concatenate([r, np.zeros(4)]), p)[7:]
    x, d, ph = s[:3]
    xw = s[3:7]
    v, dd, phd = s[7:10]
    vw = s[10:14]
    lon = [-p["a1"], -p["a1"], p["a2"], p["a2"]]
    lat = [p["w1"] / 2, -p["w1"] / 2, p["w2"] / 2, -p["w2"] / 2]
    # strut force on the body (up), per corner: -(k D + c V), D the extension
    F = [-(p[f"k{i + 1}"] * (x + lon[i] * d + lat[i] * ph - xw[i])
           + p[f"c{i + 1}"] * (v + lon[i] * dd + lat[i] * phd - vw[i])) for i in range(4)]
    assert p["m"] * acc[0] == pytest.approx(sum(F), abs=1e-8)
    assert p["Iy"] * acc[1] == pytest.approx(sum(lon[i] * F[i] for i in range(4)), abs=1e-8)
    assert p["Ix"] * acc[2] == pytest.approx(sum(lat[i] * F[i] for i in range(4)), abs=1e-8)
    for i in range(4):
        tyre = -p[f"kt{i + 1}"] * (xw[i] - r[i])
        assert p[f"m{i + 1}"] * acc[3 + i] == pytest.approx(-F[i] + tyre, abs=1e-8)


def test_symmetric_car_reduces_to_half4_with_summed_corners() -> None:
    """Equal left/right parameters and roads: no roll; heave and pitch are a half4's."""
    p = dict(P, c1=1800.0, c2=1800.0, c3=1500.0, c4=1500.0, k1=27000.0, k2=27000.0,
             k3=23000.0, k4=23000.0, m1=38.0, m2=38.0, m3=42.0, m4=42.0, kt3=210000.0,
             kt4=210000.0)
    half = get_model("half4")
    ph = dict(m=p["m"], I=p["Iy"], m1=2 * p["m1"], m2=2 * p["m3"], c1=2 * p["c1"],
              c2=2 * p["c3"], k1=2 * p["k1"], k2=2 * p["k3"], k3=2 * p["kt1"], k4=2 * p["kt3"],
              a1=p["a1"], a2=p["a2"])
    t, road7, _ = make_scenario(FULL7, "bump", duration=3.0, fs=500.0, params=p, v_kmh=15)
    t4, road4, _ = make_scenario(half, "bump", duration=3.0, fs=500.0, params=ph, v_kmh=15)
    np.testing.assert_array_equal(road7["r3"], road4["r2"])
    x0_7 = np.zeros(14)
    x0_7[[0, 1, 7, 8]] = [0.02, 0.01, -0.05, 0.03]
    x0_4 = np.zeros(8)
    x0_4[[0, 1, 4, 5]] = [0.02, 0.01, -0.05, 0.03]
    full = simulate(FULL7, p, t, road7, x0_7)
    ref = simulate(half, ph, t4, road4, x0_4)
    assert np.max(np.abs(full["phi"])) < 1e-12
    for c7, c4 in (("x", "x"), ("delta", "delta"), ("x1", "x1"), ("x2", "x1"), ("x3", "x2"),
                   ("x4", "x2"), ("x_ddot", "x_ddot"), ("delta_ddot", "delta_ddot")):
        scale = np.max(np.abs(ref[c4]))
        assert np.max(np.abs(full[c7] - ref[c4])) < 1e-9 * scale, c7


def test_struts_tyres_and_static_loads() -> None:
    p = dict(P, a1=1.1, a2=1.5, w1=1.5, w2=1.6, m3=45.0)
    struts = FULL7.strut_sites(p)
    tyres = FULL7.tyre_sites(p)
    assert [s.c_name for s in struts] == ["c1", "c2", "c3", "c4"]
    assert [s.k_name for s in struts] == ["k1", "k2", "k3", "k4"]
    assert [s.k_name for s in tyres] == ["kt1", "kt2", "kt3", "kt4"]
    # corner 3 (rear left): body point x + a2 delta + w2/2 phi, extension minus x3
    q = np.array([0.01, 0.02, 0.03, 0.0, 0.0, 0.004, 0.0])
    assert struts[2].g @ q == pytest.approx(0.01 + 1.5 * 0.02 + 0.8 * 0.03 - 0.004)
    assert struts[1].g @ q == pytest.approx(0.01 - 1.1 * 0.02 - 0.75 * 0.03)
    loads = [s.load for s in tyres]
    total = (p["m"] + sum(p[f"m{i}"] for i in range(1, 5))) * GRAVITY
    assert sum(loads) == pytest.approx(total)
    # centre of mass at mid-track: left = right on each axle; front/rear by a2 : a1
    assert loads[0] == pytest.approx(loads[1])
    front_body = loads[0] + loads[1] - (p["m1"] + p["m2"]) * GRAVITY
    rear_body = loads[2] + loads[3] - (p["m3"] + p["m4"]) * GRAVITY
    assert front_body / rear_body == pytest.approx(p["a2"] / p["a1"])
    # the tyre coordinate is the compression r_i - x_i
    X = np.zeros((1, 14))
    X[0, 3 + 3] = 0.01
    U = np.zeros((1, 8))
    U[0, 3] = 0.03
    assert tyres[3].coordinate(X, U)[0][0] == pytest.approx(0.02)


def test_deflections_are_the_corner_extensions() -> None:
    t, road, x0 = make_scenario(FULL7, "iso8608", duration=1.0, fs=200.0, v_kmh=40)
    out = simulate(FULL7, P, t, road, x0)
    d = FULL7.deflections(out, P)
    assert list(d) == [f"{c} strut" for c in ("front-left", "front-right", "rear-left", "rear-right")]
    ref = out["x"] + P["a2"] * out["delta"] - P["w2"] / 2 * out["phi"] - out["x4"]
    np.testing.assert_allclose(d["rear-right strut"], ref, atol=1e-15)
    # without the wheels no strut deflection can be formed
    assert FULL7.deflections({c: out[c] for c in ("x", "delta", "phi")}, P) == {}


def test_roads_rear_follows_front_and_tracks_differ() -> None:
    v = 36.0
    t, road, _ = make_scenario(FULL7, "iso8608", duration=3.0, fs=1000.0, v_kmh=v)
    k = int(round((P["a1"] + P["a2"]) / (v / 3.6) * 1000.0))
    np.testing.assert_allclose(road["r3"][k:], road["r1"][:-k], atol=2e-5 * np.ptp(road["r1"]))
    np.testing.assert_allclose(road["r4"][k:], road["r2"][:-k], atol=2e-5 * np.ptp(road["r2"]))
    assert np.corrcoef(road["r1"], road["r2"])[0, 1] < 0.9      # left and right tracks differ
    t, bump, _ = make_scenario(FULL7, "bump", duration=3.0, fs=1000.0, v_kmh=v)
    np.testing.assert_array_equal(bump["r1"], bump["r2"])        # a bump spans the width
    assert np.argmax(bump["r3"]) - np.argmax(bump["r1"]) == k


def test_measured_front_roads_give_the_rear_ones() -> None:
    t = np.arange(0, 2, 0.001)
    r1, r2 = np.sin(2 * np.pi * 1.3 * t), np.cos(2 * np.pi * 0.7 * t)
    road = measured_road(FULL7, t, {"r1": r1, "r2": r2}, P, v_kmh=36.0)
    k = int(round(2.6 / 10.0 / 0.001))
    np.testing.assert_allclose(road["r3"][k:], r1[:-k], atol=1e-12)
    np.testing.assert_allclose(road["r4"][k:], r2[:-k], atol=1e-12)
    with pytest.raises(Exception, match="no road column 'r2'"):
        measured_road(FULL7, t, {"r1": r1}, P)


def _measurement(noise: float = 0.0, seed: int = 0, duration: float = 4.0) -> Measurement:
    t, road, x0 = make_scenario(FULL7, "iso8608", duration=duration, fs=500.0, params=P, v_kmh=40)
    out = simulate(FULL7, P, t, road, x0)
    chans = list(FULL7.coords) + [f"{c}_dot" for c in FULL7.coords]
    rng = np.random.default_rng(seed)
    meas = {c: out[c] + noise * np.std(out[c]) * rng.standard_normal(t.size) for c in chans}
    return Measurement(t=t, road=road, measured=meas, source="synthetic")


@pytest.mark.slow
@pytest.mark.parametrize("cost", ["sse", "frobenius"])
def test_noise_free_identification_from_half_the_truth(cost: str) -> None:
    """Masses, inertias and geometry known; 12 springs, dampers and tyres from 0.5x truth."""
    params = Parameters.for_model(FULL7, fix={k: P[k] for k in FULL7.known},
                                  init={k: 0.5 * P[k] for k in FREE})
    res, _ = fit(OutputErrorProblem(FULL7, _measurement(), cost=cost), params)
    assert res.success and res.identifiable
    assert sorted(res.stderr) == sorted(FREE)
    for k in FREE:
        assert res.params[k] == pytest.approx(P[k], rel=0.01), k
        assert res.params[k] == pytest.approx(P[k], rel=1e-5), k


@pytest.mark.slow
def test_noisy_identification_reports_honest_standard_errors() -> None:
    params = Parameters.for_model(FULL7, fix={k: P[k] for k in FULL7.known},
                                  init={k: 0.5 * P[k] for k in FREE})
    res, _ = fit(OutputErrorProblem(FULL7, _measurement(noise=0.05, seed=3), cost="sse"), params)
    assert res.success and res.identifiable
    z = np.array([(res.params[k] - P[k]) / res.stderr[k] for k in FREE])
    assert np.all(np.isfinite(z)) and np.all([res.stderr[k] > 0 for k in FREE])
    assert np.max(np.abs(z)) < 4.5            # 12 parameters: none beyond ~4 sigma
    assert np.sqrt(np.mean(z ** 2)) < 2.5      # the spread matches the reported errors
    for k in FREE:
        assert res.params[k] == pytest.approx(P[k], rel=0.1), k


@pytest.mark.slow
def test_cli_simulate_encode_identify(tmp_path: Path) -> None:
    """simulate -> CSV -> identify; encode (model inferred) -> CAN log -> identify."""
    csv = tmp_path / "f7.csv"
    r = _suspid("simulate", "--model", "full7", "--scenario", "iso8608", "--duration", "3",
                "--fs", "500", "--speed", "40", "--out", str(csv))
    assert r.returncode == 0, r.stderr
    fix = [a for k in FULL7.known for a in ("--fix", f"{k}={P[k]}")]
    r = _suspid("identify", "--model", "full7", "--input", str(csv), *fix, "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["model"] == "full7" and out["identifiable"] and sorted(out["stderr"]) == sorted(FREE)
    for k in FREE:
        assert out["params"][k] == pytest.approx(P[k], rel=0.01), k
    log = tmp_path / "f7.log"
    r = _suspid("encode", "--input", str(csv), "--out", str(log))
    assert r.returncode == 0, r.stderr
    assert "model full7" in r.stdout
    r = _suspid("identify", "--model", "full7", "--input", str(log), *fix, "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    # 1501 samples x (SN_Sync + 11 FC_* frames) + SN_Status at 10 Hz (31)
    assert out["frames"]["accepted"] == 1501 * 12 + 31
    assert sum(out["frames"]["rejected"].values()) == 0
    meas = read_measurement(csv, FULL7)
    assert set(FULL7.coords) <= set(meas.measured)
    for k in FREE:       # quantised to the DBC's resolution: a little off, well within 5 %
        assert out["params"][k] == pytest.approx(P[k], rel=0.05), k


@pytest.mark.parametrize("cost", ["sse", "frobenius"])
def test_closed_form_x0_projection_equals_explicit_least_squares(cost: str) -> None:
    """The identifier's fast path (closed-form initial-state projection) on the full car."""
    meas = _measurement(noise=0.3, seed=2, duration=2.0)
    w = {c: 1.0 + i for i, c in enumerate(FULL7.state_names)}
    prob = OutputErrorProblem(FULL7, meas, cost=cost, x0="estimate", weights=w)
    p = {k: v * 1.1 for k, v in P.items()}
    fast = prob.predict(p)
    prob._full = False  # force the explicit (N, p, n) regressor path
    slow = prob.predict(p)
    np.testing.assert_allclose(fast.Y, slow.Y, rtol=0, atol=1e-11 * np.max(np.abs(slow.Y)))
    np.testing.assert_allclose(fast.x0, slow.x0, rtol=1e-8, atol=1e-12)
