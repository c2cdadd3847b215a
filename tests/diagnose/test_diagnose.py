"""diagnose names the undeclared effect, estimates it, lowers the residual, fixes c1/k1."""
from __future__ import annotations

import math
import warnings
from dataclasses import replace

import numpy as np
import pytest

from estimator.diagnose import diagnose
from estimator.identify import Parameters
from suspid.errors import InputError
from suspid.io.csvio import Measurement
from suspid.models import get_model

from ..conftest import TABLE1
from .conftest import make_measurement

#: evaluation budget of the baseline (linear) fit: converged long before, keeps the suite lean
BASELINE_FEV = 1200
ROUGH = {k: 0.7 * TABLE1[k] for k in ("c1", "k1", "c2", "k2")}   # rough start, masses known

# (effect spec, scenario, scenario options, truth of the effect's numeric parameters)
CASES = [
    ("coulomb_friction:F=80", "bump", {}, {"F": 80}),
    ("coulomb_friction:F=250", "iso8608", {"v_kmh": 50}, {"F": 250}),
    ("asymmetric_damping:c_rebound=1600,c_compression=640", "bump", {}, {"c_rebound": 1600, "c_compression": 640}),
    ("asymmetric_damping:c_rebound=1400,c_compression=900", "iso8608", {"v_kmh": 50}, {"c_rebound": 1400, "c_compression": 900}),
    ("quadratic_damping:c_quad=1500", "bump", {}, {"c_quad": 1500}),
    ("quadratic_damping:c_quad=4000", "curb", {"h": 0.08}, {"c_quad": 4000}),
    ("progressive_spring:k_cubic=1e8", "bump", {}, {"k_cubic": 1e8}),
    ("progressive_spring:k_cubic=3e8", "iso8608", {"v_kmh": 60, "road_class": "D"}, {"k_cubic": 3e8}),
    ("bump_stop:gap=0.01,k_stop=300000", "bump", {}, {"gap": 0.01, "k_stop": 3e5}),
    ("bump_stop:gap=0.02,k_stop=150000", "curb", {"h": 0.12}, {"gap": 0.02, "k_stop": 1.5e5}),
    ("tire_liftoff", "curb", {"h": -0.1}, {}),
    ("tire_liftoff", "bump", {"h": -0.06, "v_kmh": 40}, {}),   # a 6 cm pothole at 40 km/h
    ("sensor_delay:channels=x2+x2_dot,delay_s=0.008", "bump", {}, {"delay_s": 0.008}),
    ("sensor_delay:channels=x1,delay_s=0.02", "iso8608", {"v_kmh": 50}, {"delay_s": 0.02}),
    ("sensor_offset:channel=x1,offset=0.003", "bump", {}, {"offset": 0.003}),
    ("sensor_offset:channel=x2,offset=-0.002", "curb", {"h": 0.05}, {"offset": -0.002}),
]


def _params() -> Parameters:
    return Parameters.for_model(get_model("quarter2"), fix={"m1": TABLE1["m1"], "m2": TABLE1["m2"]},
                                init=ROUGH)


@pytest.mark.slow
@pytest.mark.parametrize("spec,scenario,opts,truth", CASES, ids=[f"{c[0].split(':')[0]}-{c[1]}" for c in CASES])
def test_names_and_estimates_the_undeclared_effect(spec: str, scenario: str, opts: dict, truth: dict) -> None:
    meas = make_measurement([spec], scenario, **opts)
    res = diagnose(get_model("quarter2"), meas, _params(), maxfev=BASELINE_FEV)
    out = res.to_json()
    name = spec.split(":")[0]
    assert out["effect"] is not None, out["evidence"]["verdict"]
    assert out["effect"]["name"] == name, out["evidence"]["verdict"]
    got = out["effect"]["params"]
    for k, v in truth.items():
        assert math.isclose(got[k], v, rel_tol=0.25), (k, got[k], v)
    if "channels" in got:
        assert sorted(got["channels"]) == sorted(spec.split("channels=")[1].split(",")[0].split("+"))
    if "channel" in got:
        assert got["channel"] == spec.split("channel=")[1].split(",")[0]
    # the residual falls on every channel and in the cost
    b, a = out["baseline"], out["augmented"]
    assert a["cost"] < b["cost"]
    assert sum(a["rms_residual"][c] / b["rms_residual"][c] for c in b["rms_residual"]) < len(b["rms_residual"])
    # the base parameters come back: symmetric part of the damper for asymmetric damping
    c1 = 0.5 * (truth["c_rebound"] + truth["c_compression"]) if name == "asymmetric_damping" else TABLE1["c1"]
    assert math.isclose(a["params"]["c1"], c1, rel_tol=0.05), a["params"]
    assert math.isclose(a["params"]["k1"], TABLE1["k1"], rel_tol=0.05), a["params"]
    ev = out["evidence"]
    assert ev["candidates"][name]["refit"]["accepted"] is True


@pytest.mark.parametrize("scenario,opts,noise", [("bump", {}, 0.01), ("iso8608", {"v_kmh": 50}, 0.02),
                                                 ("curb", {}, 0.0)])
def test_no_effect_reports_none(scenario: str, opts: dict, noise: float) -> None:
    meas = make_measurement([], scenario, noise=noise, seed=3, **opts)
    out = diagnose(get_model("quarter2"), meas, _params(), maxfev=BASELINE_FEV).to_json()
    assert out["effect"] is None, out["evidence"]
    assert "no missing effect" in out["evidence"]["verdict"], out["evidence"]["verdict"]
    assert math.isclose(out["baseline"]["params"]["c1"], TABLE1["c1"], rel_tol=0.05)
    assert out["augmented"]["params"] == out["baseline"]["params"]


def test_structured_but_unexplained_residual_is_said_plainly() -> None:
    # an engine-shake force on the body at 9 Hz: structured, but no library effect explains it
    def shake(t: float, x: np.ndarray, u: np.ndarray, p: dict) -> np.ndarray:
        return np.array([120.0 * math.sin(2 * math.pi * 9.0 * t), 0.0])

    meas = make_measurement([], "bump", noise=0.005, extra_force=shake)
    out = diagnose(get_model("quarter2"), meas, _params(), maxfev=BASELINE_FEV).to_json()
    ev = out["evidence"]
    assert out["effect"] is None
    assert ev["structured_channels"], ev["channels"]
    assert ev.get("unexplained") is True
    assert "no candidate effect explains it" in ev["verdict"]


def test_body_only_baseline_is_not_the_twin() -> None:
    """Body channels alone, the fit started at the truth's twin (the suspension and tyre
    swapped: the same response, the same cost): the baseline fits the twin's twin too and
    reports the truth by the rule, naming the other fit."""
    m = get_model("quarter2")
    full = make_measurement([], "bump", noise=0.0, seed=3)
    meas = Measurement(t=full.t, road=full.road, source=full.source,
                       measured={c: full.measured[c] for c in ("x1", "x1_dot")})
    twin = m.twin(TABLE1, {"x1"})
    assert twin is not None
    params = Parameters.for_model(m, fix={"m1": TABLE1["m1"], "m2": TABLE1["m2"]},
                                  init={k: twin.params[k] for k in ("c1", "k1", "c2", "k2")})
    out = diagnose(m, meas, params, maxfev=BASELINE_FEV).to_json()
    for k in ("c1", "k1", "c2", "k2"):
        assert math.isclose(out["baseline"]["params"][k], TABLE1[k], rel_tol=1e-5), k
    assert any(w.startswith("two fits explain the record") for w in out["warnings"])
    assert out["effect"] is None


def test_short_or_non_uniform_record_is_an_input_error_naming_it() -> None:
    """The residual analysis smooths with a 7-sample window and the refits step on a
    uniform grid: a shorter record, or a time base with a gap, is an input error naming the
    record (a 2-row CSV once ended in scipy's savgol ValueError, a non-uniform one in a
    message naming neither file nor grid). Jitter within a quarter step is resampled
    (``tests/diagnose/test_jitter.py``)."""
    meas = make_measurement([], fs=200.0, duration=0.4, noise=0.0)
    m = get_model("quarter2")
    params = Parameters.for_model(m, fix={"m1": TABLE1["m1"]})
    short = replace(meas, t=meas.t[:6], measured={k: v[:6] for k, v in meas.measured.items()},
                    road={k: v[:6] for k, v in meas.road.items()}, source="short.csv")
    with pytest.raises(InputError, match=r"^short\.csv: diagnose needs at least 7 samples, got 6$"):
        diagnose(m, short, params, maxfev=50)
    keep = np.arange(meas.t.size) != 40
    gap = replace(meas, t=meas.t[keep], measured={k: v[keep] for k, v in meas.measured.items()},
                  road={k: v[keep] for k, v in meas.road.items()}, source="gap.csv")
    with pytest.raises(InputError, match=r"^gap\.csv: diagnose needs uniformly spaced samples"):
        diagnose(m, gap, params, maxfev=50)


@pytest.mark.parametrize("n", [7, 12])
def test_record_shorter_than_the_analysis_lags_is_diagnosed(n: int) -> None:
    """Cross-correlation and whiteness lags are cut to the record (a 12-sample record once
    broke the cross-correlation's slicing)."""
    meas = make_measurement([], fs=200.0, duration=0.8, noise=0.0)
    k = slice(100, 100 + n)
    rec = replace(meas, t=meas.t[k], measured={c: v[k] for c, v in meas.measured.items()},
                  road={c: v[k] for c, v in meas.road.items()})
    m = get_model("quarter2")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        res = diagnose(m, rec, Parameters.for_model(m, fix={"m1": TABLE1["m1"]}), maxfev=60)
    assert res.baseline is not None
    assert all(abs(v["rho"]) <= 1.0 + 1e-12 for ch in res.evidence["cross_correlation"].values()
               for v in ch.values())
