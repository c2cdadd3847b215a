"""The identifier's optimised hot path equals the explicit computation."""
from __future__ import annotations

import numpy as np
import pytest

from estimator.doe.design import experiments
from estimator.doe.runner import measurement
from estimator.identify import OutputErrorProblem
from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement
from suspid.models import get_model
from suspid.simulate import modal_form, modal_powers, simulate


@pytest.mark.parametrize("name", ["quarter1", "quarter2", "half4"])
@pytest.mark.parametrize("cost", ["sse", "frobenius"])
def test_closed_form_x0_projection_equals_explicit_least_squares(name: str, cost: str) -> None:
    m = get_model(name)
    for e in experiments(m)[::9]:
        meas, _ = measurement(m, e, noise=0.3, seed=e.id)
        w = {c: 1.0 + i for i, c in enumerate(m.state_names)}
        prob = OutputErrorProblem(m, meas, cost=cost, x0="estimate", weights=w)
        p = {k: v * 1.1 for k, v in e.truth.items()}
        fast = prob.predict(p)
        prob._full = False  # force the explicit (N, p, n) regressor path
        slow = prob.predict(p)
        np.testing.assert_allclose(fast.Y, slow.Y, rtol=0, atol=1e-11 * np.max(np.abs(slow.Y)))
        np.testing.assert_allclose(fast.x0, slow.x0, rtol=1e-8, atol=1e-12)


def test_road_path_with_estimated_x0_recovers_the_initial_state() -> None:
    m = get_model("quarter2")
    p = m.defaults()
    t, road, _ = make_scenario(m, "bump", duration=2.0, fs=500.0, params=p)
    x0 = np.array([0.01, -0.02, 0.1, 0.05])
    out = simulate(m, p, t, road, x0)
    meas = Measurement(t=t, road=road, measured={c: out[c] for c in ("x1", "x2", "x1_dot")})
    pred = OutputErrorProblem(m, meas, cost="frobenius").predict(p)
    np.testing.assert_allclose(pred.x0, x0, atol=1e-9)
    assert np.max(np.abs(pred.residual)) < 1e-10


def test_modal_powers_running_product_matches_exp() -> None:
    m = get_model("half4")
    e = experiments(m)[10]
    modal = modal_form(m, e.truth)
    P = modal_powers(modal, 0.01, 5000)
    ref = np.exp(np.outer(np.arange(5000) * 0.01, modal.lam))
    np.testing.assert_allclose(P, ref, rtol=1e-11, atol=1e-300)
