"""`suspid diagnose` on a record whose sample times jitter: resampled with a warning; a gap
is still rejected."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

from estimator.diagnose import diagnose
from estimator.identify.regrid import grid_jitter, to_uniform_grid
from tools.synthetic_record import synthetic_record
from estimator.identify import Parameters
from suspid.io.csvio import Measurement
from suspid.models import get_model

from ..conftest import TABLE1

FS, DURATION = 200.0, 1.6
ROUGH = {k: 0.7 * TABLE1[k] for k in ("c1", "k1", "c2", "k2")}


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "suspid", *args], capture_output=True, text=True,
                          timeout=300)


def jittered_times(frac: float, seed: int = 1) -> np.ndarray:
    """200 Hz sample times, each moved by up to ``frac`` of a step (first and last exact)."""
    n = int(round(DURATION * FS))
    d = np.random.default_rng(seed).uniform(-frac, frac, n) / FS
    d[0] = d[-1] = 0.0
    return np.arange(n) / FS + d


def bump_road(t: np.ndarray, height: float = 0.1, length: float = 3.0, v_kmh: float = 20.0,
              t0: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """The seed's raised-cosine bump and its rate at the times ``t`` (m, m/s)."""
    v = v_kmh / 3.6
    s = v * (t - t0)
    on = (s >= 0) & (s <= length)
    r = np.where(on, 0.5 * height * (1 - np.cos(2 * np.pi * s / length)), 0.0)
    rd = np.where(on, 0.5 * height * 2 * np.pi * v / length * np.sin(2 * np.pi * s / length), 0.0)
    return r, rd


def test_a_jittered_csv_is_resampled_and_diagnosed(tmp_path: Path) -> None:
    # the quarter car simulated exactly on a jittered grid (a measured road's own times)
    t = jittered_times(0.2)
    r, rd = bump_road(t)
    road = tmp_path / "road.csv"
    np.savetxt(road, np.column_stack([t, r, rd]), delimiter=",", header="t,r,r_dot", comments="",
               fmt="%.9g")
    csv = tmp_path / "jittered.csv"
    truth = [f"--param={k}={v}" for k, v in TABLE1.items()]
    p = run("simulate", "--model", "quarter2", "--road", str(road), *truth, "--noise", "0.005",
            "--seed", "3", "--out", str(csv))
    assert p.returncode == 0, p.stderr
    p = run("diagnose", "--model", "quarter2", "--input", str(csv), "--fix", f"m1={TABLE1['m1']}",
            "--fix", f"m2={TABLE1['m2']}", *[f"--init={k}={v}" for k, v in ROUGH.items()],
            "--maxfev", "1200", "--json")
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["effect"] is None
    assert out["evidence"]["verdict"].startswith("residual is white noise")
    for k in ("c1", "k1", "k2"):
        assert math.isclose(out["augmented"]["params"][k], TABLE1[k], rel_tol=0.03), k
    note = [w for w in out["warnings"] if "jitter" in w]
    assert len(note) == 1 and str(csv) in note[0] and "cubic spline" in note[0]
    # the jitter named is the one put in: up to a fifth of the 5 ms step
    assert "0.000998 s" in note[0] or "0.001 s" in note[0], note[0]
    assert f"warning: {note[0]}" in p.stderr


def test_friction_is_found_through_jitter() -> None:
    # the truth sampled exactly at jittered times (an 8 kHz record, every 40th sample moved
    # by up to 9 fine steps: 0.225 of the 200 Hz step), then noise
    up = 40
    fine = synthetic_record("quarter2", ["coulomb_friction:F=120"], "bump", params=TABLE1,
                            fs=FS * up, duration=DURATION, noise=0.0)
    n = int(round(DURATION * FS))
    rng = np.random.default_rng(7)
    idx = np.arange(n) * up + rng.integers(-9, 10, n)
    idx[0], idx[-1] = 0, (n - 1) * up
    noise = np.random.default_rng(101)
    meas = Measurement(fine.t[idx], {k: v[idx] for k, v in fine.road.items()},
                       {k: v[idx] + 0.005 * np.std(v[idx]) * noise.standard_normal(n)
                        for k, v in fine.measured.items()}, [], "jittered-friction")
    h, jit = grid_jitter(meas.t)
    assert 0.2 * h < jit <= 0.25 * h
    model = get_model("quarter2")
    params = Parameters.for_model(model, fix={"m1": TABLE1["m1"], "m2": TABLE1["m2"]}, init=ROUGH)
    res = diagnose(model, meas, params, maxfev=1200)
    out = res.to_json()
    assert out["effect"] is not None and out["effect"]["name"] == "coulomb_friction"
    assert math.isclose(out["effect"]["params"]["F"], 120, rel_tol=0.1)
    for k in ("c1", "k1"):
        assert math.isclose(out["augmented"]["params"][k], TABLE1[k], rel_tol=0.03), k
    assert any("jittered-friction" in w and "jitter" in w for w in out["warnings"])
    assert res.record is not None and np.allclose(np.diff(res.record.t), h, rtol=1e-9, atol=1e-12)


def test_resampling_keeps_missing_samples_and_is_accurate() -> None:
    t = jittered_times(0.24, seed=4)
    y = np.sin(2 * np.pi * 12 * t)
    y[50] = np.nan
    out, note = to_uniform_grid(Measurement(t, {}, {"x1": y}, [], "rec"))
    assert note is not None
    assert np.isnan(out.measured["x1"][50]) and np.isfinite(out.measured["x1"][51])
    ok = np.isfinite(out.measured["x1"])
    err = out.measured["x1"][ok] - np.sin(2 * np.pi * 12 * out.t[ok])
    # a spline's error (linear interpolation would be ~1e-2 here)
    assert float(np.max(np.abs(err[5:-5]))) < 3e-4
    # a uniform record is returned as it is
    same, none = to_uniform_grid(Measurement(np.arange(20) / FS, {}, {"x1": np.ones(20)}, [], "u"))
    assert none is None and np.array_equal(same.t, np.arange(20) / FS)


def test_a_gap_is_still_rejected(tmp_path: Path) -> None:
    csv = tmp_path / "uniform.csv"
    truth = [f"--param={k}={v}" for k, v in TABLE1.items()]
    p = run("simulate", "--model", "quarter2", "--scenario", "bump", "--duration", "1.6", "--fs", "200",
            *truth, "--noise", "0.005", "--out", str(csv))
    assert p.returncode == 0, p.stderr
    lines = csv.read_text().splitlines()
    gap = tmp_path / "gap.csv"
    gap.write_text("\n".join(lines[:101] + lines[102:]) + "\n")   # one sample dropped
    p = run("diagnose", "--model", "quarter2", "--input", str(gap), "--fix", "m1=275", "--fix", "m2=27",
            "--json")
    assert p.returncode == 2
    assert p.stdout == ""
    err = p.stderr.strip()
    assert "\n" not in err and "Traceback" not in err
    assert err.startswith(f"error: {gap}: diagnose needs uniformly spaced samples")
    assert "0.005 to 0.01 s" in err
    # a gap in the middle puts a sample half a step off the same-count grid
    t = np.loadtxt(gap, delimiter=",", skiprows=1, usecols=0)
    h, jit = grid_jitter(t)
    assert jit > 0.45 * h


def test_simulate_with_an_effect_resamples_a_jittered_road(tmp_path: Path) -> None:
    # the nonlinear simulation steps on a uniform grid: a jittered road is put on the grid
    # (warning), and the result equals the same run on the road sampled there exactly
    t = jittered_times(0.2)
    n = t.size
    grid = t[0] + (t[-1] - t[0]) / (n - 1) * np.arange(n)
    files = {}
    for name, tt in (("jit", t), ("uni", grid)):
        r, rd = bump_road(tt)
        files[name] = tmp_path / f"{name}_road.csv"
        np.savetxt(files[name], np.column_stack([tt, r, rd]), delimiter=",",
                   header="t,r,r_dot", comments="", fmt="%.12g")
    out = {}
    for name, road in files.items():
        csv = tmp_path / f"{name}.csv"
        p = run("simulate", "--model", "quarter2", "--road", str(road), "--effect",
                "coulomb_friction:F=100", "--out", str(csv))
        assert p.returncode == 0, p.stderr
        out[name] = (np.genfromtxt(csv, delimiter=",", names=True), p.stderr)
    data, err = out["jit"]
    assert f"{files['jit']}: sample times jitter by up to" in err and "on that grid" in err
    assert "jitter" not in out["uni"][1]
    np.testing.assert_allclose(data["t"], out["uni"][0]["t"], rtol=0, atol=1e-9)
    peak = float(np.max(np.abs(out["uni"][0]["x1"])))
    assert float(np.max(np.abs(data["x1"] - out["uni"][0]["x1"]))) < 1e-3 * peak
