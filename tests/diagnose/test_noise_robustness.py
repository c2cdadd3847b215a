"""diagnose at higher noise and small effects: dry friction is named, a sub-sample time shift is not.

The records are the worked example's (``docs/closing-the-loop.md``): the seed's Table 1
quarter car over the speed bump, 2 s at 250 Hz, masses known, the other parameters started
at 0.7 x the truth, the noise drawn as ``suspid simulate --noise N --seed S`` draws it
(``noise_seed=S``). Before the fix every friction record here came out as ``effect: null``
with c1 20-60 % high, or as a ``sensor_delay`` of 1-2 ms: the noise smoothing of an
interpolated half-sample shift made a spurious delay screen above friction, which then
fell below half the best screen and was never refitted.

At 3 % noise the positions-only cost leaves c1 within about +-9 % over seeds even at the
cost's own optimum (seeds 2, 5 and 6 of ``python tools/noise_sweep.py``, refitted
from the truth), so the c1/k1 check runs on seeds whose optimum is within 5 %; the
detection rate over eight seeds is in the doc's noise table.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.diagnose import diagnose
from estimator.diagnose.core import Thresholds, select_for_refit
from estimator.diagnose.residuals import Screen, shift_allpass
from estimator.identify import Parameters
from suspid.models import get_model
from suspid.effects.sensor import _shift

from ..conftest import TABLE1
from .conftest import make_measurement

ROUGH = {k: 0.7 * TABLE1[k] for k in ("c1", "k1", "c2", "k2")}


def _diagnose(spec: str, noise: float, seed: int) -> dict:
    meas = make_measurement([spec], "bump", fs=250.0, duration=2.0, noise=noise, seed=seed,
                            noise_seed=seed)
    params = Parameters.for_model(get_model("quarter2"), fix={"m1": TABLE1["m1"], "m2": TABLE1["m2"]},
                                  init=ROUGH)
    return diagnose(get_model("quarter2"), meas, params).to_json()


# (F, noise, noise seed): before the fix null (c1 +22 %, +21 %, +61 %, +55 %)
@pytest.mark.parametrize("F,noise,seed", [(60, 0.01, 7), (60, 0.01, 1), (150, 0.03, 7), (150, 0.03, 1)],
                         ids=["F60-1pct-seed7", "F60-1pct-seed1", "F150-3pct-seed7", "F150-3pct-seed1"])
def test_friction_is_named_at_higher_noise_and_small_F(F: float, noise: float, seed: int) -> None:
    out = _diagnose(f"coulomb_friction:F={F}", noise, seed)
    ev = out["evidence"]
    assert out["effect"] is not None, ev["verdict"]
    assert out["effect"]["name"] == "coulomb_friction", ev["verdict"]
    assert math.isclose(out["effect"]["params"]["F"], F, rel_tol=0.25), out["effect"]
    b, a = out["baseline"], out["augmented"]
    assert a["cost"] < b["cost"]
    assert sum(a["rms_residual"][c] / b["rms_residual"][c] for c in b["rms_residual"]) < len(b["rms_residual"])
    for k in ("c1", "k1"):
        assert math.isclose(a["params"][k], TABLE1[k], rel_tol=0.05), (k, a["params"])
    assert b["params"]["c1"] > 1.15 * TABLE1["c1"]   # the linear model hid the friction in c1


# (F, noise, noise seed): before the fix sensor_delay of 1.6 ms, 1.1 ms; null at seed 7
@pytest.mark.parametrize("F,noise,seed", [(150, 0.05, 2), (60, 0.03, 2), (150, 0.05, 7)],
                         ids=["F150-5pct-seed2", "F60-3pct-seed2", "F150-5pct-seed7"])
@pytest.mark.slow
def test_high_noise_names_no_subsample_delay(F: float, noise: float, seed: int) -> None:
    out = _diagnose(f"coulomb_friction:F={F}", noise, seed)
    ev = out["evidence"]
    # friction or, where the noise hides it, a plain "no candidate explains it" — never a delay
    assert out["effect"] is None or out["effect"]["name"] == "coulomb_friction", out["effect"]
    if out["effect"] is None:
        assert ev.get("unexplained") is True and "no candidate effect explains it" in ev["verdict"]
    delay = ev["candidates"]["sensor_delay"]
    assert delay.get("refit", {}).get("accepted") is not True
    if "refit" in delay and any(c not in ("x1", "x2") for c in delay["refit"]["params"]["channels"]):
        # a refit on a channel outside the sse cost is judged against the linear model
        # refitted on the same channels, not against the positions-only baseline
        assert delay["refit"]["reference"].startswith("declared linear model fitted on")
    # friction itself is always refitted when it is the best physical candidate
    assert "refit" in ev["candidates"]["coulomb_friction"]


def test_allpass_shift_keeps_the_noise() -> None:
    # the mechanism of the spurious delays: interpolating white noise halfway between
    # samples smooths it (cubic spline: -25 % variance, linear: -50 %); the all-pass shift
    # used by the delay screen and refit does not, and shifts a smooth signal exactly
    rng = np.random.default_rng(0)
    h = 0.004
    t = np.arange(5000) * h
    y = rng.standard_normal(t.size)
    for frac in (0.5, 1.5):
        ok = slice(20, -20)
        spline = _shift(t, y, frac * h)[ok]
        assert np.var(spline) < 0.8
        assert np.var(np.interp(t + frac * h, t, y)[ok]) < 0.55
        assert abs(np.var(shift_allpass(t, y, frac * h)[ok]) / np.var(y[ok]) - 1) < 0.02
    np.testing.assert_allclose(shift_allpass(t, y, 3 * h)[:-3], y[3:], atol=1e-9)
    assert np.all(np.isnan(shift_allpass(t, y, 3 * h)[-3:]))
    s = np.sin(2 * np.pi * 12 * t) * np.exp(-t) + 0.2 * t
    got = shift_allpass(t, s, 0.0013)
    want = np.sin(2 * np.pi * 12 * (t + 0.0013)) * np.exp(-(t + 0.0013)) + 0.2 * (t + 0.0013)
    err = np.abs(got - want)
    assert np.nanmax(err) < 5e-3 and np.nanmax(err[10:-10]) < 5e-5 and np.nanmax(err[30:-30]) < 5e-6


def test_selection_ranks_physical_and_sensor_candidates_separately() -> None:
    # the screens of the 1 %-noise friction record before the fix: a spurious delay took 16 %
    # of the residual force and friction (7 %) fell below half of it
    screens = [Screen("coulomb_friction", "force", 0.069, 5.0, True, {"F": 62.0}),
               Screen("quadratic_damping", "force", 0.042, 4.0, False, {"c_quad": -1314.0}),
               Screen("bump_stop", "force", 0.004, 1.0, True, {"gap": 0.01, "k_stop": 1e4}),
               Screen("sensor_delay", "force", 0.163, float("nan"), True,
                      {"channels": ["x1_dot"], "delay_s": 0.002}),
               Screen("sensor_offset", "output", 0.002, 1.0, True, {"channel": "x1", "offset": 0.0})]
    first, fallback = select_for_refit(screens, {}, Thresholds())
    assert [s.name for s in first] == ["coulomb_friction", "sensor_delay"]
    assert fallback == []
    # a best physical candidate below min_screen is still tried when nothing else is accepted
    screens[0].explained = 0.011
    first, fallback = select_for_refit(screens, {}, Thresholds())
    assert [s.name for s in first] == ["sensor_delay"]
    assert [s.name for s in fallback] == ["coulomb_friction"]
    # ... but not when the residual force points to an effect that cannot be identified
    _, fallback = select_for_refit(screens, {"asymmetric_damping": "both struts differ"}, Thresholds())
    assert fallback == []
