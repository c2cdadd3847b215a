"""diagnose on quarter1, half4 and full7: every applicable effect, no effect, unexplained,
not identifiable.

Same protocol as the quarter2 tests (``test_diagnose.py``): 1.6 s at 200 Hz, 0.5 % white
noise on every channel, masses (and the half and full car's inertias and geometry: the
model's ``known`` set) known, the free stiffnesses and dampings started at 0.7 x the truth.
The half and full car's truths have different parameters at every corner so a mix-up of
struts shows.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from estimator.diagnose import diagnose
from estimator.diagnose.corners import SiteRestricted
from estimator.identify import Parameters
from suspid.models import get_model
from suspid.effects import Effect, PhysicalEffect, parse_effect

from .conftest import make_measurement

BASELINE_FEV = 1200
#: quarter1 truth: the documented defaults (m = 300 kg, c = 1500 N s/m, k = 20000 N/m)
Q1 = get_model("quarter1").defaults()
#: half4 truth: defaults with different front/rear suspension and tyres
H4 = dict(get_model("half4").defaults(), c1=1800.0, c2=2400.0, k1=28000.0, k2=35000.0,
          k3=220000.0, k4=190000.0)
#: full7 truth: defaults with a different damper at every corner, springs and tyres mixed
F7 = dict(get_model("full7").defaults(), c1=1800.0, c2=2000.0, c3=1500.0, c4=1700.0,
          k1=27000.0, k2=29000.0, kt1=210000.0, kt4=190000.0)
TRUTH = {"quarter1": Q1, "half4": H4, "full7": F7}
FIXED = {"quarter1": ("m",), "half4": ("m", "I", "m1", "m2", "a1", "a2"),
         "full7": tuple(get_model("full7").known)}
FREE = {"quarter1": ("c", "k"), "half4": ("c1", "c2", "k1", "k2", "k3", "k4"),
        "full7": tuple(k for k in get_model("full7").param_names if k not in FIXED["full7"])}
BOTH = ["front strut", "rear strut"]
FOUR = ["front-left strut", "front-right strut", "rear-left strut", "rear-right strut"]
TYRES = ["front-left tyre", "front-right tyre", "rear-left tyre", "rear-right tyre"]


def _params(model: str) -> Parameters:
    p = TRUTH[model]
    return Parameters.for_model(get_model(model), fix={k: p[k] for k in FIXED[model]},
                                init={k: 0.7 * p[k] for k in FREE[model]})


def _in(strut: str, spec: str) -> Effect:
    """A library strut effect acting in one strut of the half car only."""
    eff = parse_effect(spec)
    if not isinstance(eff, PhysicalEffect):
        raise TypeError(spec)
    return SiteRestricted(eff, [strut])


def _run(model: str, effects: list[Any], scenario: str, **opts: Any) -> dict[str, Any]:
    meas = make_measurement(effects, scenario, model=model, params=TRUTH[model], **opts)
    return diagnose(get_model(model), meas, _params(model), maxfev=BASELINE_FEV).to_json()


# (model, injected effect, scenario, scenario options, sites the effect acts at)
CASES: list[tuple[str, Any, str, dict[str, Any], list[str] | None]] = [
    ("quarter1", "coulomb_friction:F=100", "bump", {}, ["strut"]),
    ("quarter1", "coulomb_friction:F=250", "iso8608", {"v_kmh": 50}, ["strut"]),
    ("quarter1", "asymmetric_damping:c_rebound=2000,c_compression=800", "bump", {}, ["strut"]),
    ("quarter1", "asymmetric_damping:c_rebound=1800,c_compression=1100", "iso8608", {"v_kmh": 50}, ["strut"]),
    ("quarter1", "quadratic_damping:c_quad=1500", "bump", {}, ["strut"]),
    ("quarter1", "quadratic_damping:c_quad=3000", "curb", {"h": 0.08}, ["strut"]),
    ("quarter1", "progressive_spring:k_cubic=3e6", "bump", {}, ["strut"]),
    ("quarter1", "progressive_spring:k_cubic=5e6", "iso8608", {"v_kmh": 60, "road_class": "D"}, ["strut"]),
    ("quarter1", "bump_stop:gap=0.02,k_stop=100000", "bump", {}, ["strut"]),
    ("quarter1", "bump_stop:gap=0.03,k_stop=60000", "curb", {"h": 0.12}, ["strut"]),
    ("quarter1", "tire_liftoff", "curb", {"h": -0.3}, ["tyre"]),
    ("quarter1", "tire_liftoff", "bump", {"h": -0.3, "v_kmh": 30}, ["tyre"]),
    ("quarter1", "sensor_delay:channels=x_dot,delay_s=0.01", "bump", {}, None),
    ("quarter1", "sensor_delay:channels=x+x_dot,delay_s=0.015", "iso8608", {"v_kmh": 50}, None),
    ("quarter1", "sensor_offset:channel=x,offset=0.003", "bump", {}, None),
    ("quarter1", "sensor_offset:channel=x_dot,offset=0.01", "curb", {"h": 0.05}, None),
    ("half4", "coulomb_friction:F=150", "bump", {}, BOTH),
    ("half4", "coulomb_friction:F=200", "curb", {"h": 0.08}, BOTH),
    ("half4", "quadratic_damping:c_quad=2000", "bump", {}, BOTH),
    ("half4", "quadratic_damping:c_quad=3000", "iso8608", {"v_kmh": 50}, BOTH),
    ("half4", "progressive_spring:k_cubic=3e6", "bump", {}, BOTH),
    ("half4", "progressive_spring:k_cubic=5e6", "iso8608", {"v_kmh": 60, "road_class": "D"}, BOTH),
    ("half4", "bump_stop:gap=0.02,k_stop=200000", "bump", {}, BOTH),
    ("half4", "bump_stop:gap=0.015,k_stop=150000", "curb", {"h": 0.12}, BOTH),
    ("half4", "tire_liftoff", "curb", {"h": -0.1}, ["front tyre", "rear tyre"]),
    ("half4", "tire_liftoff", "bump", {"h": 0.15, "v_kmh": 40}, ["front tyre", "rear tyre"]),
    ("half4", "sensor_delay:channels=x1+x1_dot,delay_s=0.008", "bump", {}, None),
    ("half4", "sensor_delay:channels=x2,delay_s=0.015", "iso8608", {"v_kmh": 50}, None),
    ("half4", "sensor_delay:channels=delta+delta_dot,delay_s=0.01", "curb", {"h": 0.05}, None),
    ("half4", "sensor_offset:channel=delta,offset=0.002", "bump", {}, None),
    ("half4", "sensor_offset:channel=x2,offset=-0.002", "curb", {"h": 0.05}, None),
    # one corner: a sticking front strut, an asymmetric rear damper
    ("half4", _in("front strut", "coulomb_friction:F=200"), "bump", {}, ["front strut"]),
    ("half4", _in("rear strut", "asymmetric_damping:c_rebound=3400,c_compression=1400"), "bump", {},
     ["rear strut"]),
    # the full car: strut effects on all four struts, lift-off of all four tyres, sensors
    # (the bump and curb are the same under both sides: roll stays numerically zero)
    ("full7", "coulomb_friction:F=150", "bump", {}, FOUR),
    ("full7", "quadratic_damping:c_quad=2500", "iso8608", {"v_kmh": 50}, FOUR),
    ("full7", "bump_stop:gap=0.02,k_stop=200000", "bump", {}, FOUR),
    ("full7", "tire_liftoff", "curb", {"h": -0.1}, TYRES),
    ("full7", "sensor_delay:channels=x3+x3_dot,delay_s=0.01", "iso8608", {"v_kmh": 50}, None),
    ("full7", "sensor_offset:channel=phi,offset=0.002", "iso8608", {"v_kmh": 50}, None),
    ("full7", _in("front-left strut", "coulomb_friction:F=200"), "iso8608", {"v_kmh": 50},
     ["front-left strut"]),
]


def _id(case: tuple[str, Any, str, dict[str, Any], list[str] | None]) -> str:
    model, eff, scenario, _, sites = case
    name = eff.split(":")[0] if isinstance(eff, str) else eff.name
    where = f"-{sites[0].rsplit(' ', 1)[0]}" if isinstance(eff, SiteRestricted) and sites else ""
    return f"{model}-{name}{where}-{scenario}"


@pytest.mark.slow
@pytest.mark.parametrize("model,injected,scenario,opts,sites", CASES, ids=[_id(c) for c in CASES])
def test_names_and_estimates_the_effect(model: str, injected: Any, scenario: str, opts: dict[str, Any],
                                        sites: list[str] | None) -> None:
    eff = parse_effect(injected) if isinstance(injected, str) else injected
    out = _run(model, [injected], scenario, **opts)
    ev = out["evidence"]
    assert out["effect"] is not None, ev["verdict"]
    assert out["effect"]["name"] == eff.name, ev["verdict"]
    got = out["effect"]["params"]
    assert set(got) == set(eff.values)
    for k, v in eff.values.items():
        if isinstance(v, float):
            assert math.isclose(got[k], v, rel_tol=0.25), (k, got[k], v)
        elif isinstance(v, list):
            assert sorted(got[k]) == sorted(v)
        else:
            assert got[k] == v
    assert ev["candidates"][eff.name]["refit"]["accepted"] is True
    assert ev.get("effect_sites") == sites
    if isinstance(injected, SiteRestricted):
        assert any("only" in w and sites[0] in w for w in out["warnings"]), out["warnings"]
    # the residual falls: the cost (unchanged when the effect only touches channels outside
    # the sse cost, i.e. velocities) and the RMS of the channels on average and where it acts
    b, a = out["baseline"], out["augmented"]
    affected = eff.affected() if hasattr(eff, "affected") else list(b["rms_residual"])
    if any(c in get_model(model).coords for c in affected):
        assert a["cost"] < b["cost"]
    else:
        assert a["cost"] <= 1.01 * b["cost"]
    assert sum(a["rms_residual"][c] / b["rms_residual"][c] for c in b["rms_residual"]) < len(b["rms_residual"])
    for c in affected:
        assert a["rms_residual"][c] < b["rms_residual"][c], c
    # the base stiffnesses and dampings come back (the damper an asymmetric one replaces: its
    # symmetric part)
    truth = dict(TRUTH[model])
    if eff.name == "asymmetric_damping":
        cname = "c" if model == "quarter1" else {"front strut": "c1", "rear strut": "c2"}[sites[0]]
        truth[cname] = 0.5 * (eff.values["c_rebound"] + eff.values["c_compression"])
    for k in FREE[model]:
        assert math.isclose(a["params"][k], truth[k], rel_tol=0.05), (k, a["params"][k], truth[k])


@pytest.mark.parametrize("model", ["quarter1", "half4"])
@pytest.mark.parametrize("scenario,opts,noise", [("bump", {}, 0.01), ("iso8608", {"v_kmh": 50}, 0.02),
                                                 ("curb", {}, 0.005), ("curb", {}, 0.0)])
def test_no_effect_reports_none(model: str, scenario: str, opts: dict[str, Any], noise: float) -> None:
    # half4 on the curb at 0.5 % noise: the wheel velocities (outside the sse cost) carry the
    # echo of the fit's parameter error; it must not read as a missing effect
    out = _run(model, [], scenario, noise=noise, seed=3, **opts)
    assert out["effect"] is None, out["evidence"]["verdict"]
    assert "no missing effect" in out["evidence"]["verdict"], out["evidence"]["verdict"]
    assert out["augmented"]["params"] == out["baseline"]["params"]
    for k in FREE[model]:
        assert math.isclose(out["baseline"]["params"][k], TRUTH[model][k], rel_tol=0.05), k


def _shake_q1(t: float, x: np.ndarray, u: np.ndarray, p: dict[str, float]) -> np.ndarray:
    return np.array([150.0 * math.sin(2 * math.pi * 9.0 * t)])


def _shake_h4(t: float, x: np.ndarray, u: np.ndarray, p: dict[str, float]) -> np.ndarray:
    return np.array([300.0 * math.sin(2 * math.pi * 9.0 * t), 150.0 * math.sin(2 * math.pi * 7.0 * t),
                     0.0, 0.0])


@pytest.mark.parametrize("model,shake", [("quarter1", _shake_q1), ("half4", _shake_h4)])
def test_structured_but_unexplained_residual_is_said_plainly(model: str, shake: Any) -> None:
    # an engine shake on the body (heave, and pitch for the half car): structured, but no
    # library effect explains it
    meas = make_measurement([], "bump", model=model, params=TRUTH[model], extra_force=shake)
    out = diagnose(get_model(model), meas, _params(model), maxfev=BASELINE_FEV).to_json()
    ev = out["evidence"]
    assert out["effect"] is None, ev["verdict"]
    assert ev["structured_channels"], ev["channels"]
    assert ev.get("unexplained") is True
    assert "no candidate effect explains it" in ev["verdict"]
    if model == "half4":   # says what the model could not have found either
        assert "not identifiable with half4" in ev["verdict"]


@pytest.mark.slow
@pytest.mark.parametrize("scenario,opts", [("bump", {}), ("iso8608", {"v_kmh": 50})])
def test_half4_asymmetric_dampers_in_both_struts_are_not_guessed(scenario: str, opts: dict[str, Any]) -> None:
    # both dampers asymmetric, each around its own symmetric part (c1 = 1800, c2 = 2400): one
    # (c_rebound, c_compression) pair cannot express it, so diagnose must say so, not pick
    # the front strut's pair (which alone "explains" two thirds of the residual)
    effects = [_in("front strut", "asymmetric_damping:c_rebound=2571,c_compression=1029"),
               _in("rear strut", "asymmetric_damping:c_rebound=3429,c_compression=1371")]
    out = _run("half4", effects, scenario, **opts)
    ev = out["evidence"]
    assert out["effect"] is None, ev["verdict"]
    assert ev.get("unexplained") is True
    assert "asymmetric_damping" in ev["not_identifiable"]
    assert "asymmetric_damping in every strut" in ev["verdict"]
    assert "cannot be identified with half4" in ev["verdict"]
    per = ev["candidates"]["asymmetric_damping"]["screen"]["per_site"]["sites"]
    assert per["front strut"]["c_rebound"] > per["front strut"]["c_compression"]
    assert per["rear strut"]["c_rebound"] > per["rear strut"]["c_compression"]
    assert "asymmetric_damping (both struts)" in ev["limits"]


@pytest.mark.parametrize("symmetric", [False, True])
def test_full7_no_effect_reports_none(symmetric: bool) -> None:
    # a left/right symmetric car on a road the same under both sides (the bump) never rolls:
    # the roll channels are round-off, neither structure nor evidence
    # (evidence.silent_channels)
    truth = get_model("full7").defaults() if symmetric else F7
    meas = make_measurement([], "bump" if symmetric else "iso8608", model="full7", params=truth,
                            noise=0.01, seed=3, **({} if symmetric else {"v_kmh": 50}))
    params = Parameters.for_model(get_model("full7"), fix={k: truth[k] for k in FIXED["full7"]},
                                  init={k: 0.7 * truth[k] for k in FREE["full7"]})
    out = diagnose(get_model("full7"), meas, params, maxfev=BASELINE_FEV).to_json()
    assert out["effect"] is None, out["evidence"]["verdict"]
    assert "no missing effect" in out["evidence"]["verdict"], out["evidence"]["verdict"]
    assert out["evidence"].get("silent_channels", []) == (["phi", "phi_dot"] if symmetric else [])
    assert "asymmetric_damping (all struts)" in out["evidence"]["limits"]
    for k in FREE["full7"]:
        assert math.isclose(out["baseline"]["params"][k], truth[k], rel_tol=0.05), k


def test_quarter1_tire_liftoff_says_what_it_means() -> None:
    # quarter1 has no wheel: the lift-off it finds is the whole corner leaving the road
    out = _run("quarter1", ["tire_liftoff"], "curb", h=-0.3)
    assert out["effect"]["name"] == "tire_liftoff"
    assert "tire_liftoff (wheel hop)" in out["evidence"]["limits"]
    assert any("quarter1 has no wheel" in w for w in out["warnings"]), out["warnings"]
