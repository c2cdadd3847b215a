"""The effect library: registry matches the contract, laws have the documented signs, injection."""
from __future__ import annotations

import numpy as np
import pytest

from suspid.errors import UsageError
from suspid.excitation import make_scenario
from suspid.models import get_model
from suspid.simulate import simulate
from suspid.effects import (EFFECT_NAMES, REGISTRY, PhysicalEffect, effects_for, inject,
                                   make_effect, parse_effect)

from ..conftest import TABLE1

CONTRACT = {"coulomb_friction": ["F"], "asymmetric_damping": ["c_rebound", "c_compression"],
            "quadratic_damping": ["c_quad"], "progressive_spring": ["k_cubic"],
            "bump_stop": ["gap", "k_stop"], "tire_liftoff": [], "sensor_delay": ["channels", "delay_s"],
            "sensor_offset": ["channel", "offset"]}


def test_registry_is_the_contract_table() -> None:
    assert list(EFFECT_NAMES) == list(CONTRACT)
    for name, params in CONTRACT.items():
        assert [p.name for p in REGISTRY[name].params] == params


def test_parse_and_errors() -> None:
    e = parse_effect("sensor_delay:channels=x2+x2_dot,delay_s=0.008")
    assert e.values == {"channels": ["x2", "x2_dot"], "delay_s": 0.008}
    assert e.to_json() == {"name": "sensor_delay", "params": {"channels": ["x2", "x2_dot"], "delay_s": 0.008}}
    assert parse_effect("tire_liftoff").values == {}
    with pytest.raises(UsageError, match="unknown effect"):
        parse_effect("magic:F=1")
    with pytest.raises(UsageError, match="unknown parameter"):
        parse_effect("coulomb_friction:G=1")
    with pytest.raises(UsageError, match="> 0"):
        parse_effect("coulomb_friction:F=-3")
    with pytest.raises(UsageError, match="missing"):
        parse_effect("bump_stop:gap=0.01")
    with pytest.raises(UsageError, match="not available for model half4"):
        inject(get_model("half4"), ["asymmetric_damping:c_rebound=1,c_compression=2"])
    with pytest.raises(UsageError, match="unknown channel"):
        inject(get_model("quarter2"), ["sensor_offset:channel=x9,offset=1"])


def _strut_force(name: str, d: float, dd: float, **v: float) -> float:
    m = get_model("quarter2")
    e = make_effect(name, **v)
    assert isinstance(e, PhysicalEffect)
    site = m.strut_sites(TABLE1)[0]
    return e.law(site, TABLE1)(d, dd)


def test_law_signs() -> None:
    # friction resists the motion: extension (d' > 0) gives a force resisting extension
    assert _strut_force("coulomb_friction", 0.0, 0.5, F=100) == pytest.approx(100, rel=1e-6)
    assert _strut_force("coulomb_friction", 0.0, -0.5, F=100) == pytest.approx(-100, rel=1e-6)
    # asymmetric damping: total damper force c_rebound d' in rebound, c_compression d' in compression
    c1 = TABLE1["c1"]
    assert _strut_force("asymmetric_damping", 0, 0.2, c_rebound=2000, c_compression=500) + c1 * 0.2 == pytest.approx(400)
    assert _strut_force("asymmetric_damping", 0, -0.2, c_rebound=2000, c_compression=500) + c1 * -0.2 == pytest.approx(-100)
    assert _strut_force("quadratic_damping", 0, -0.3, c_quad=1000) == pytest.approx(-90)
    assert _strut_force("progressive_spring", 0.02, 0, k_cubic=1e8) == pytest.approx(800)
    # bump stop only in compression beyond the gap, pushing the strut apart (negative = extending)
    assert _strut_force("bump_stop", -0.005, 0, gap=0.01, k_stop=1e5) == 0.0
    assert _strut_force("bump_stop", 0.05, 0, gap=0.01, k_stop=1e5) == 0.0
    assert _strut_force("bump_stop", -0.03, 0, gap=0.01, k_stop=1e5) == pytest.approx(-2000)


def test_tire_liftoff_only_when_pulling() -> None:
    m = get_model("quarter2")
    e = make_effect("tire_liftoff")
    site = m.tyre_sites(TABLE1)[0]
    phi = e.law(site, TABLE1)
    W = (TABLE1["m1"] + TABLE1["m2"]) * 9.81
    assert phi(0.0, 0.0) == 0.0          # static contact
    s_free = -2 * W / TABLE1["k2"]       # wheel 2x the static deflection above the road
    assert phi(s_free, 0.0) == pytest.approx(W)   # cancels the pull beyond the static load
    # the generalised force acts on the wheel only
    Q = e.generalized_force(m, np.array([0.0, -s_free, 0, 0]), np.array([0.0, 0.0]), TABLE1)
    assert Q[0, 0] == 0 and Q[0, 1] == pytest.approx(W)


def test_rhs_carries_the_effect_and_base_model_unchanged() -> None:
    m = get_model("quarter2")
    inj = inject(m, ["coulomb_friction:F=150"])
    x = np.array([0.01, 0.0, 0.3, 0.0])
    u = np.zeros(2)
    d_lin = m.rhs(0.0, x, u, TABLE1)
    d_eff = inj.model.rhs(0.0, x, u, TABLE1)
    # friction 150 N resisting extension: body decelerates by F/m1, wheel accelerates by F/m2
    assert d_eff[2] - d_lin[2] == pytest.approx(-150 * np.tanh(30) / TABLE1["m1"])
    assert d_eff[3] - d_lin[3] == pytest.approx(150 * np.tanh(30) / TABLE1["m2"])
    assert m.extra_force == []


def test_sensor_effects_round_trip() -> None:
    t = np.arange(500) / 250.0
    y = np.sin(2 * np.pi * 1.3 * t)
    inj = inject(get_model("quarter2"), ["sensor_delay:channels=x2,delay_s=0.02",
                                          "sensor_offset:channel=x1,offset=0.004"])
    out = inj.measure(t, {"x1": y, "x2": y})
    assert np.allclose(out["x1"], y + 0.004)
    assert np.allclose(out["x2"][10:], np.sin(2 * np.pi * 1.3 * (t[10:] - 0.02)), atol=1e-3)
    back = inj.sensor[0].compensate(t, out)
    ok = ~np.isnan(back["x2"])
    assert ok.sum() >= 490 and np.allclose(back["x2"][ok][5:], y[ok][5:], atol=2e-3)


def test_availability_follows_the_structure() -> None:
    # every strut effect wherever there are struts, the tyre effect wherever there are tyres;
    # asymmetric_damping only where one damper coefficient describes every strut
    assert effects_for(get_model("quarter1")) == list(EFFECT_NAMES)
    assert effects_for(get_model("quarter2")) == list(EFFECT_NAMES)
    assert effects_for(get_model("half4")) == [n for n in EFFECT_NAMES if n != "asymmetric_damping"]
    assert "c1 and c2 differ" in str(REGISTRY["asymmetric_damping"].unavailable_reason(get_model("half4")))
    assert effects_for(get_model("half4"), kinds=("sensor",)) == ["sensor_delay", "sensor_offset"]


@pytest.mark.parametrize("model", ["quarter1", "half4"])
def test_other_models(model: str) -> None:
    m = get_model(model)
    p = m.defaults()
    for name in effects_for(m, kinds=("physical",)):
        cls = REGISTRY[name]
        vals = {"F": 50, "c_rebound": 2000, "c_compression": 800, "c_quad": 500, "k_cubic": 1e7,
                "gap": 0.01, "k_stop": 1e5}
        e = make_effect(name, **{k.name: vals[k.name] for k in cls.params})
        inj = inject(m, [e])
        x = np.full(m.n_states, 0.02)
        x[: len(m.coords)] = -0.05   # compressed below the road? (wheel/body down)
        u = np.zeros(2 * len(m.roads))
        dx = inj.model.rhs(0.0, x, u, p)
        assert np.all(np.isfinite(dx))


def test_influence_is_zero_only_for_an_effect_the_record_never_engages() -> None:
    """``Injection.influence``: per effect, the largest relative RMS change of a channel."""
    model = get_model("quarter2")
    p = model.defaults()
    t, road, x0 = make_scenario(model, "bump", duration=1.0, fs=200.0, params=p)
    inj = inject(model, ["bump_stop:gap=30,k_stop=1e5", "coulomb_friction:F=100",
                         "sensor_offset:channel=x1,offset=0.003"])
    far, friction, offset = inj.influence(p, t, road, x0)
    assert far < 1e-9
    assert friction > 1e-3
    base = simulate(model, p, t, road, x0)
    assert offset == pytest.approx(0.003 / float(np.sqrt(np.mean(base["x1"] ** 2))), rel=1e-9)
