"""Ride heights (strut extensions ``d``/``dN``): the CSV reader, the simulated outputs
against the contract's definitions, ``suspid simulate --channels`` and the identifier."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from estimator.identify.problem import OutputErrorProblem
from suspid.cli import main
from suspid.errors import InputError, UsageError
from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement, read_measurement, write_measurement
from suspid.models import MODELS, get_model
from suspid.simulate import outputs, road_matrix, simulate, simulate_states

ALL = list(MODELS)   # every registered model gets the same tests


def _contract_heights(name: str, p: dict[str, float], ch: dict[str, np.ndarray],
                      rate: bool) -> dict[str, np.ndarray]:
    """The ride heights as CONTRACT.md defines them, written out per model (no Site used)."""
    s = "_dot" if rate else ""
    g = {k: ch[f"{k}{s}"] for k in get_model(name).coords + get_model(name).roads
         if f"{k}{s}" in ch}
    if name == "quarter1":
        return {f"d{s}": g["x"] - g.get("y", 0.0)}
    if name == "quarter2":
        return {f"d{s}": g["x1"] - g["x2"]}
    if name == "half4":
        return {f"d1{s}": g["x"] - p["a1"] * g["delta"] - g["x1"],
                f"d2{s}": g["x"] + p["a2"] * g["delta"] - g["x2"]}
    assert name == "full7"
    out = {}
    for i, (along, lat) in enumerate([(-p["a1"], p["w1"] / 2), (-p["a1"], -p["w1"] / 2),
                                      (p["a2"], p["w2"] / 2), (p["a2"], -p["w2"] / 2)]):
        corner = g["x"] + along * g["delta"] + lat * g["phi"]
        out[f"d{i + 1}{s}"] = corner - g[f"x{i + 1}"]
    return out


@pytest.mark.parametrize("name", ALL)
def test_names_units_and_sets(name: str) -> None:
    m = get_model(name)
    n = len(m.strut_sites(m.defaults()))
    assert m.ride_heights == (("d",) if n == 1 else tuple(f"d{i}" for i in range(1, n + 1)))
    for d in m.ride_heights:
        assert m.column_units(d) == ("m",) and m.column_units(f"{d}_dot") == ("m/s",)
        assert m.column_units(f"{d}_ddot") == ()
    prod = m.channel_set("production")
    body = {"quarter1": ["x"], "quarter2": ["x1"], "half4": ["x", "delta"],
            "full7": ["x", "delta", "phi"]}[name]
    assert list(prod) == [f"{c}_ddot" for c in body] + list(m.ride_heights)
    assert list(m.channel_set("accelerometers")) == [f"{c}_ddot" for c in m.coords]
    with pytest.raises(UsageError, match="production"):
        m.channel_set("everything")


@pytest.mark.parametrize("name", ALL)
def test_simulated_ride_heights_are_the_contract_deflections(name: str) -> None:
    m = get_model(name)
    p = dict(m.defaults())
    t, road, _ = make_scenario(m, "bump", duration=1.5, fs=500.0, params=p, v_kmh=30)
    x0 = np.linspace(0.01, 0.03, m.n_states)
    out = simulate(m, p, t, road, x0)
    for rate in (False, True):
        for c, want in _contract_heights(name, p, out, rate).items():
            np.testing.assert_allclose(out[c], want, rtol=0, atol=1e-13 * (1 + np.abs(want).max()))
            assert np.ptp(want) > 1e-3, c   # the record moves the strut
    # outputs() from states and road gives the same, and no road columns
    U = road_matrix(m, t, road)
    X = simulate_states(m, p, t, U, x0)
    got = outputs(m, p, X, U)
    assert not set(got) & set(m.roads)
    for c in m.ride_height_channels:
        np.testing.assert_allclose(got[c], out[c], rtol=0, atol=1e-12)


def test_ride_heights_follow_the_geometry() -> None:
    """half4 with other axle distances: the struts sit elsewhere on the body."""
    m = get_model("half4")
    p = dict(m.defaults(), a1=0.9, a2=1.8)
    t, road, _ = make_scenario(m, "bump", duration=1.0, fs=500.0, params=p)
    out = simulate(m, p, t, road, np.linspace(0.01, 0.02, m.n_states))
    for c, want in _contract_heights("half4", p, out, False).items():
        np.testing.assert_allclose(out[c], want, atol=1e-14)


def _write(path: Path, rows: list[list[str]]) -> Path:
    with path.open("w", newline="") as fh:
        csv.writer(fh).writerows(rows)
    return path


@pytest.mark.parametrize("name", ALL)
def test_csv_reader_takes_ride_heights_as_measured_channels(tmp_path: Path, name: str) -> None:
    m = get_model(name)
    acc = m.channel_set("production")[0]
    heights = list(m.ride_heights)
    header = ["t [s]", acc] + [f"{d} [m]" for d in heights] + [f"{heights[0]}_dot (m/s)"]
    rows = [header]
    for k in range(5):
        vals = [f"{0.01 * k}", f"{0.5 * k}"] + [f"{0.001 * (k + j)}" for j in range(len(heights))]
        vals.append("" if k == 2 else f"{-0.02 * k}")   # a missing sample
        rows.append(vals)
    meas = read_measurement(_write(tmp_path / "rh.csv", rows), m)
    assert set(meas.measured) == {acc, f"{heights[0]}_dot", *heights}
    # the missing sample is named, as every measured channel's are
    assert meas.road == {} and len(meas.warnings) == 1
    assert f"column '{heights[0]}_dot': 1 missing sample at t 0.02 s" in meas.warnings[0]
    for j, d in enumerate(heights):
        np.testing.assert_allclose(meas.measured[d], 0.001 * (np.arange(5) + j))
    rate = meas.measured[f"{heights[0]}_dot"]
    assert math.isnan(rate[2]) and rate[3] == pytest.approx(-0.06)
    # only ride heights: a valid record
    only = read_measurement(_write(tmp_path / "only.csv", [["t", heights[-1]], ["0", "0.01"],
                                                           ["0.01", "0.02"]]), m)
    assert list(only.measured) == [heights[-1]]


@pytest.mark.parametrize("name", ALL)
def test_csv_reader_ride_height_errors_and_units(tmp_path: Path, name: str) -> None:
    m = get_model(name)
    d = m.ride_heights[-1]
    # another unit: ignored with a warning naming the unit expected
    meas = read_measurement(_write(tmp_path / "mm.csv", [["t", "x_ddot" if "x" in m.coords
                                                          else "x1_ddot", f"{d} [mm]"],
                                                         ["0", "1", "2"], ["0.01", "1", "3"]]), m)
    assert d not in meas.measured
    assert any(f"{d} in 'mm', expected m" in w for w in meas.warnings)
    with pytest.raises(InputError, match=rf"bad.csv:3: column '{d}_dot': expected a number"):
        read_measurement(_write(tmp_path / "bad.csv", [["t", f"{d}_dot"], ["0", "1"],
                                                       ["0.01", "fast"]]), m)
    with pytest.raises(InputError, match=rf"no measured channel .*{d}_dot"):
        read_measurement(_write(tmp_path / "none.csv", [["t", f"{d}_ddot"], ["0", "1"],
                                                        ["0.01", "2"]]), m)


@pytest.mark.parametrize("name", ALL)
def test_simulate_named_sets_write_no_road_and_take_noise(tmp_path: Path, name: str,
                                                          capsys: pytest.CaptureFixture) -> None:
    m = get_model(name)
    clean = tmp_path / "clean.csv"
    noisy = tmp_path / "noisy.csv"
    base = ["simulate", "--model", name, "--scenario", "iso8608", "--duration", "2", "--fs",
            "500", "--seed", "3"]
    assert main(base + ["--channels", "production", "--out", str(clean)]) == 0
    assert main(base + ["--channels", "production", "--noise", "0.2", "--out", str(noisy)]) == 0
    a = read_measurement(clean, m)
    b = read_measurement(noisy, m)
    header = clean.read_text().splitlines()[0].split(",")
    assert header == ["t", *m.channel_set("production")]
    assert a.road == {} and b.road == {}
    # the clean record is the simulation's: ride heights vs the contract's deflections
    p = m.defaults()
    t, road, x0 = make_scenario(m, "iso8608", duration=2.0, fs=500.0, params=p, seed=3)
    ref = simulate(m, p, t, road, x0)
    for c in m.ride_heights:
        np.testing.assert_allclose(a.measured[c], ref[c], atol=1e-9 * np.abs(ref[c]).max() + 1e-12)
    for c in m.channel_set("production"):
        ratio = np.std(b.measured[c] - a.measured[c]) / np.std(a.measured[c])
        assert ratio == pytest.approx(0.2, rel=0.15), c
    acc = tmp_path / "acc.csv"
    assert main(base + ["--channels", "accelerometers", "--out", str(acc)]) == 0
    assert acc.read_text().splitlines()[0].split(",") == ["t"] + [f"{c}_ddot" for c in m.coords]
    # an explicit list keeps the road columns (the record then carries its input)
    both = tmp_path / "both.csv"
    assert main(base + ["--channels", f"{m.ride_heights[0]},{m.ride_heights[0]}_dot",
                        "--out", str(both)]) == 0
    cols = both.read_text().splitlines()[0].split(",")
    assert set(m.roads) <= set(cols) and f"{m.ride_heights[0]}_dot" in cols
    assert main(base + ["--channels", "production,x9", "--out", str(both)]) == 2
    assert "x9" in capsys.readouterr().err


@pytest.mark.parametrize("name", ALL)
def test_problem_compares_ride_heights_with_the_road(name: str) -> None:
    m = get_model(name)
    p = m.defaults()
    t, road, x0 = make_scenario(m, "bump", duration=2.0, fs=200.0, params=p, t0=0.2)
    out = simulate(m, p, t, road, x0)
    heights = list(m.ride_height_channels)
    meas = Measurement(t, dict(road), {c: out[c] for c in heights})
    pr = OutputErrorProblem(m, meas, cost="frobenius")
    assert pr.channels == heights
    pred = pr.predict(p)
    scale = max(float(np.abs(out[c]).max()) for c in heights)
    assert np.abs(pred.residual).max() < 1e-9 * scale
    worse = dict(p, **{m.strut_sites(p)[0].c_name: 0.6 * p[m.strut_sites(p)[0].c_name]})
    assert pr.normalized_ss(worse) > 1e-4
    # sse compares the positions: the ride heights themselves
    assert OutputErrorProblem(m, meas, cost="sse").channels == list(m.ride_heights)
    # the stacked Jacobian path (no road, initial state given) agrees point by point
    x0 = np.linspace(0.01, 0.03, m.n_states)   # released from a displaced state
    free = Measurement(t, {}, {c: simulate(m, p, t, None, x0)[c] for c in heights})
    pf = OutputErrorProblem(m, free, cost="frobenius", x0=x0)
    R = pf.residual_vectors([p, worse, p])
    np.testing.assert_allclose(R[1], pf.residual_vector(worse), rtol=1e-10, atol=1e-14)
    assert np.abs(R[0]).max() < 1e-9 * scale and np.abs(R[1]).max() > 1e-4 * scale


@pytest.mark.parametrize("name", ALL)
def test_identify_from_body_acceleration_ride_heights_and_road(tmp_path: Path, name: str,
                                                               capsys: pytest.CaptureFixture) -> None:
    """The production sensors plus the road recover every damper and spring."""
    m = get_model(name)
    p = m.defaults()
    t, road, x0 = make_scenario(m, "iso8608", duration=4.0, fs=200.0, params=p, seed=1)
    out = simulate(m, p, t, road, x0)
    cols = {c: out[c] for c in m.input_names}
    cols.update({c: out[c] for c in m.channel_set("production")})
    path = tmp_path / "prod.csv"
    write_measurement(path, t, cols)
    fix = [a for k in m.known for a in ("--fix", f"{k}={p[k]}")]
    assert main(["identify", "--model", name, "--input", str(path), *fix, "--cost", "frobenius",
                 "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["success"]
    assert set(m.ride_heights) <= set(res["rms_residual"])
    for k in res["stderr"]:
        assert res["params"][k] == pytest.approx(p[k], rel=0.01), k


def test_problem_without_ride_heights_leaves_them_out_with_a_warning() -> None:
    """The monitor window's problem (``ride_heights=False``) fits the motion channels."""
    m = get_model("quarter2")
    p = m.defaults()
    t, road, x0 = make_scenario(m, "bump", duration=1.0, fs=200.0, t0=0.2)
    out = simulate(m, p, t, road, x0)
    meas = Measurement(t, dict(road), {c: out[c] for c in ("x1_ddot", "d", "d_dot")})
    wp = OutputErrorProblem(m, meas, cost="frobenius", ride_heights=False)
    assert wp.channels == ["x1_ddot"]
    assert any("d, d_dot not compared" in w for w in wp.warnings)
    assert np.abs(wp.predict(p).residual).max() < 1e-8
