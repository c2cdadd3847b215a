"""The fast nonlinear simulator agrees with solve_ivp on the same right-hand side."""
from __future__ import annotations

import numpy as np
import pytest

from suspid.nlsim import simulate_effects
from suspid.excitation import make_scenario
from suspid.models import get_model
from suspid.effects import inject
from suspid.simulate import simulate, simulate_ode

from ..conftest import TABLE1

CASES = [
    ("quarter2", "coulomb_friction:F=150", "bump", 1),
    ("quarter2", "bump_stop:gap=0.01,k_stop=300000", "bump", 1),
    ("quarter2", "asymmetric_damping:c_rebound=1600,c_compression=600", "iso8608", 1),
    ("quarter1", "progressive_spring:k_cubic=3e7", "bump", 1),
    ("half4", "quadratic_damping:c_quad=2000", "bump", 2),
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
