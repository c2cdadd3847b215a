"""The fast nonlinear simulator agrees with solve_ivp on the same right-hand side."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from suspid.nlsim import simulate_effects
from suspid.excitation import make_scenario
from suspid.models import MODELS, get_model
from suspid.effects import inject
from suspid.simulate import simulate, simulate_ode

from ..conftest import TABLE1

CASES = [
    ("quarter2", "coulomb_friction:F=150", "bump", 1),
    ("quarter2", "bump_stop:gap=0.01,k_stop=300000", "bump", 1),
    ("quarter2", "asymmetric_damping:c_rebound=1600,c_compression=600", "iso8608", 1),
    ("quarter1", "progressive_spring:k_cubic=3e7", "bump", 1),
    ("half4", "quadratic_damping:c_quad=2000", "bump", 2),
    ("full7", "quadratic_damping:c_quad=2000", "iso8608", 2),
]


@pytest.mark.parametrize("model,spec,scenario,sub", CASES)
def test_fast_matches_solve_ivp(model: str, spec: str, scenario: str, sub: int) -> None:
    m = get_model(model)
    p = dict(TABLE1) if model == "quarter2" else m.defaults()
    t, road, x0 = make_scenario(m, scenario, duration=0.8, fs=250, params=p)
    inj = inject(m, [spec])
    ref = simulate_ode(inj.model, p, t, road, x0)
    fast = simulate_effects(m, p, inj.physical, t, road, x0, substeps=sub)
    lin = simulate(m, p, t, road, x0)
    for c in m.coords:
        size = np.max(np.abs(lin[c] - ref[c]))      # how much the effect changes the response
        err = np.max(np.abs(fast[c] - ref[c]))
        assert size > 1e-3 * np.max(np.abs(ref[c])), "effect too small to test anything"
        assert err < 0.05 * size, (c, err, size)  # the fit uses these settings
    acc_err = np.max(np.abs(fast[f"{m.coords[0]}_ddot"] - ref[f"{m.coords[0]}_ddot"]))
    assert acc_err < 0.05 * np.max(np.abs(ref[f"{m.coords[0]}_ddot"]))


def test_no_effect_is_the_exact_linear_solution() -> None:
    m = get_model("quarter2")
    t, road, x0 = make_scenario(m, "curb", duration=1.0, fs=200, params=TABLE1)
    fast = simulate_effects(m, TABLE1, [], t, road, x0)
    lin = simulate(m, TABLE1, t, road, x0)
    for c in ("x1", "x2", "x1_dot", "x2_ddot"):
        assert np.allclose(fast[c], lin[c], rtol=0, atol=1e-9 * np.max(np.abs(lin[c])))


@pytest.mark.parametrize("name", list(MODELS))
def test_linear_part_is_the_models_forward_model_or_its_affine_pieces(name: str) -> None:
    """Without effects the fast simulator is the exact linear solution; given the model's
    affine pieces it takes A, B and M^-1 from them, to rounding the same."""
    m = get_model(name)
    p = m.defaults()
    q = {k: (v * 0.8 if m.spec(k).kind in ("damping", "stiffness") else v) for k, v in p.items()}
    t, road, x0 = make_scenario(m, "iso8608", duration=0.6, fs=250, params=p)

    def scale(out: dict, c: str) -> float:  # the largest channel of c's kind (roll may be ~0)
        order = c.count("_d")
        return max(float(np.max(np.abs(out[k]))) for k in m.channels if k.count("_d") == order)

    aff = m.affine(p)
    lin = simulate(m, q, t, road, x0)
    for pieces in (None, aff):
        fast = simulate_effects(m, q, [], t, road, x0, affine=pieces)
        for c in m.channels:
            np.testing.assert_allclose(fast[c], lin[c], rtol=0, atol=1e-9 * scale(lin, c),
                                       err_msg=c)
    eff = inject(m, ["quadratic_damping:c_quad=2000"]).physical
    ref = simulate_effects(m, q, eff, t, road, x0)
    got = simulate_effects(m, q, eff, t, road, x0, affine=aff)
    for c in m.channels:
        np.testing.assert_allclose(got[c], ref[c], rtol=0, atol=1e-9 * scale(ref, c), err_msg=c)
    # the pieces are what it uses: other pieces, another answer
    bad = replace(aff, Minv=2.0 * aff.Minv)
    moved = simulate_effects(m, q, eff, t, road, x0, affine=bad)
    c = m.coords[0]
    assert np.max(np.abs(moved[c] - ref[c])) > 1e-4 * np.max(np.abs(ref[c]))
