"""Virtual damper test: the frequency-domain EUSAMA / EGEA numbers equal a time-domain shaker."""
from __future__ import annotations

import importlib.util
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from estimator.inspection import (EGEA_CRITERION_DEG, G, PLATE_AMPLITUDE, eusama_band, inspect,
                                  quarter_car_problem, response_function)
from suspid.errors import UsageError
from suspid.models import get_model
from suspid.simulate import simulate

#: the plug-in model file of tests/plugins (a quarter car with an undamped tyre, ``qcar5``)
QCAR5_FILE = (Path(__file__).resolve().parents[1] / "plugins" / "suspid_testplugin"
              / "suspid_testplugin" / "models.py")


def qcar5():
    """The plug-in model ``qcar5``, loaded from its file (no entry point: no registry change)."""
    spec = importlib.util.spec_from_file_location("_qcar5_models", QCAR5_FILE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.QCar5()


def shaker(model, p, f, periods=60, per=200):
    """Steady-state contact force of a time-domain simulation with a sinusoidal plate."""
    t = np.arange(periods * per + 1) / (per * f)
    w = 2 * np.pi * f
    r = PLATE_AMPLITUDE * np.sin(w * t)
    out = simulate(model, p, t, {"r": r, "r_dot": PLATE_AMPLITUDE * w * np.cos(w * t)})
    F = p["k2"] * (r - out["x2"]) + p.get("c2", 0.0) * (out["r_dot"] - out["x2_dot"])
    last = slice(-10 * per - 1, None)  # ten periods after the transient died out
    return t[last], r[last], F[last]


@pytest.mark.parametrize("c1_frac", [1.0, 0.4])
def test_eusama_equals_the_time_domain_minimum_wheel_load(quarter2, c1_frac) -> None:
    p = dict(quarter2.defaults(), c1=1500.0 * c1_frac)
    res = inspect(p, quarter2)
    Fs = (p["m1"] + p["m2"]) * G
    assert res.static_load_n == pytest.approx(Fs)
    _, _, F = shaker(quarter2, p, res.eusama_f_hz)
    rh_time = 100 * (Fs + F.min()) / Fs
    assert rh_time == pytest.approx(res.eusama_pct, abs=0.2)
    # and it is the minimum over the sweep: neighbouring frequencies hold the wheel better
    for df in (-0.5, 0.5):
        _, _, F2 = shaker(quarter2, p, res.eusama_f_hz + df)
        assert 100 * (Fs + F2.min()) / Fs > res.eusama_pct - 0.2


def test_phase_equals_the_time_domain_phase(quarter2) -> None:
    p = dict(quarter2.defaults(), c1=600.0)
    for f in (2.5, 6.0, 11.0):
        t, r, F = shaker(quarter2, p, f)
        w = 2 * np.pi * f
        # phase of F relative to r = A sin(w t): project on sin and cos
        a = 2 * np.mean(F * np.sin(w * t))
        b = 2 * np.mean(F * np.cos(w * t))
        ph_time = np.degrees(np.arctan2(b, a)) % 360
        H = response_function(quarter2, p)(np.array([f]))[0]
        assert ph_time == pytest.approx(np.degrees(np.angle(H)) % 360, abs=0.2)


def test_worn_damper_fails_both_tests_good_one_passes(quarter2) -> None:
    base = quarter2.defaults()
    good = inspect(base, quarter2)
    assert good.eusama_band == "good" and good.egea_pass and good.phi_min_deg > EGEA_CRITERION_DEG
    worn = inspect(dict(base, c1=300.0), quarter2)
    assert not worn.egea_pass and worn.eusama_pct < good.eusama_pct
    fr = [inspect(dict(base, c1=base["c1"] * k), quarter2) for k in (1.0, 0.7, 0.5, 0.3)]
    assert all(a.phi_min_deg > b.phi_min_deg for a, b in zip(fr, fr[1:]))
    assert all(a.eusama_pct > b.eusama_pct for a, b in zip(fr, fr[1:]))
    assert good.f_body_hz == pytest.approx(1.2565, abs=1e-3)
    assert good.f_wheel_hz == pytest.approx(11.64, abs=0.01)


def test_bands() -> None:
    assert [eusama_band(x) for x in (0, 20, 20.5, 40, 41, 90)] == \
        ["poor", "poor", "sufficient", "sufficient", "good", "good"]


def test_liftoff_clips_at_zero(quarter2) -> None:
    res = inspect(dict(quarter2.defaults(), c1=50.0, m1=150.0), quarter2)
    assert res.eusama_pct == 0.0 and res.eusama_band == "poor"


def test_a_plugin_quarter_car_takes_the_test_and_matches_its_time_domain_shaker() -> None:
    model = qcar5()
    assert quarter_car_problem(model) is None
    p = dict(model.defaults(), c1=700.0)
    res = inspect(p, model)
    Fs = (p["m1"] + p["m2"]) * G
    assert res.static_load_n == pytest.approx(Fs, rel=1e-12)
    _, _, F = shaker(model, p, res.eusama_f_hz)
    assert 100 * (Fs + F.min()) / Fs == pytest.approx(res.eusama_pct, abs=0.2)
    f = 6.0
    t, r, F = shaker(model, p, f)
    w = 2 * np.pi * f
    ph_time = np.degrees(np.arctan2(2 * np.mean(F * np.cos(w * t)), 2 * np.mean(F * np.sin(w * t))))
    H = response_function(model, p)(np.array([f]))[0]
    assert ph_time % 360 == pytest.approx(np.degrees(np.angle(H)) % 360, abs=0.2)
    # an undamped tyre is quarter2 with c2 = 0: the same numbers from the other model
    ref = inspect(dict(p, c2=0.0), get_model("quarter2"))
    for k, v in ref.to_json().items():
        assert res.to_json()[k] == (v if isinstance(v, (bool, str)) else pytest.approx(v, rel=1e-9))


@pytest.mark.parametrize("name, missing", [("quarter1", "model quarter1 has 1 coordinates (x), expected 2"),
                                           ("half4", "model half4 has 4 coordinates"),
                                           ("full7", "model full7 has 7 coordinates")])
def test_a_model_that_is_no_quarter_car_is_refused_naming_what_it_lacks(name, missing) -> None:
    model = get_model(name)
    with pytest.raises(UsageError, match="needs a quarter car") as err:
        inspect(model.defaults(), model)
    assert missing in str(err.value)
    assert quarter_car_problem(model) == str(err.value)


class _NoTyre(type(get_model("quarter2"))):  # type: ignore[misc]
    """quarter2 whose tyre site is withheld, or carries no load."""

    def __init__(self, sites):
        super().__init__()
        self._sites = sites

    def tyre_sites(self, p):
        return list(self._sites(super().tyre_sites(p)))


@pytest.mark.parametrize("sites, missing", [
    (lambda ts: [], "has 0 tyre sites, expected 1"),
    (lambda ts: ts + ts, "has 2 tyre sites, expected 1"),
    (lambda ts: [replace(ts[0], k_name=None)], "names no tyre spring"),
    (lambda ts: [replace(ts[0], load=0.0)], "carries no static load")])
def test_the_tyre_the_test_needs_is_checked(sites, missing) -> None:
    model = _NoTyre(sites)
    with pytest.raises(UsageError, match=missing):
        inspect(model.defaults(), model)


def test_inspection_search_finds_the_dense_grid_extrema(quarter2) -> None:
    """Two nested grids + a parabolic vertex give the minimum of a 200 001-point sweep."""
    base = quarter2.defaults()
    for c1 in (1500.0, 900.0, 450.0):
        p = dict(base, c1=c1)
        res = inspect(p, quarter2)
        f = np.geomspace(2.0, 25.0, 200_001)
        H = response_function(quarter2, p)(f)
        fs = (p["m1"] + p["m2"]) * 9.80665
        rh = 100 * (fs - 0.003 * np.abs(H)) / fs
        assert res.eusama_pct == pytest.approx(max(0.0, rh.min()), abs=1e-6)
        assert res.eusama_f_hz == pytest.approx(f[np.argmin(rh)], rel=1e-4)
        fb = np.geomspace(max(2.0, res.f_body_hz), min(25.0, res.f_wheel_hz), 200_001)
        ph = np.degrees(np.unwrap(np.angle(response_function(quarter2, p)(
            np.concatenate([[1e-3], fb])))))
        ph = (ph - 360 * np.round((ph[0] - 180) / 360))[1:]
        assert res.phi_min_deg == pytest.approx(ph.min(), abs=1e-6)
