"""Residuals of several points and the Jacobians built from them equal the one-by-one
evaluations (one path: finite differences never mix two computations)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.doe.design import experiments
from tools.doe_evalbench import jacobian_one_by_one
from estimator.doe.runner import measurement
from estimator.identify import OutputErrorProblem, jacobian_log
from estimator.identify.profile import _Cost, _fd_jacobian
from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement
from suspid.models import get_model, model_names
from suspid.simulate import simulate


def _free_response(name: str, missing: bool = False) -> tuple[Measurement, dict[str, float],
                                                              np.ndarray]:
    m = get_model(name)
    e = experiments(m)[5]
    meas, _ = measurement(m, e, noise=0.2, seed=e.id)
    if missing:
        for c in meas.measured:
            meas.measured[c][40:45] = np.nan
    return meas, {k: v * 1.07 for k, v in e.truth.items()}, np.asarray(e.x0, dtype=float)


def _road(name: str) -> tuple[Measurement, dict[str, float], np.ndarray]:
    m = get_model(name)
    p0 = m.defaults()
    t, road, x0 = make_scenario(m, "bump", duration=1.0, fs=400.0, params=p0)
    out = simulate(m, p0, t, road, x0)
    rng = np.random.default_rng(2)
    meas = Measurement(t=t, road=road, measured={
        c: out[c] + 1e-4 * rng.standard_normal(t.size) for c in m.channels if c in out})
    return meas, {k: v * 1.05 for k, v in p0.items()}, np.asarray(x0, dtype=float)


def test_every_registered_model_is_covered() -> None:
    assert set(model_names()) == {"quarter1", "quarter2", "half4", "full7"}


@pytest.mark.parametrize("name", ["quarter1", "quarter2", "half4", "full7"])
@pytest.mark.parametrize("case", ["free", "road", "missing"])
@pytest.mark.parametrize("x0", ["known", "estimate"])
def test_batched_jacobian_equals_one_by_one(name: str, case: str, x0: str) -> None:
    meas, p, x0_true = _road(name) if case == "road" else _free_response(name, case == "missing")
    m = get_model(name)
    for cost in ("sse", "frobenius"):
        # unit weights with sse, per-channel weights with frobenius
        weights = None if cost == "sse" else {c: 1.0 + 0.5 * i for i, c in enumerate(m.channels)}
        prob = OutputErrorProblem(m, meas, cost=cost, x0=x0_true if x0 == "known" else "estimate",
                                  weights=weights)
        free = list(p)
        points = []
        for k in free:
            for s in (-1e-5, 1e-5):
                q = dict(p)
                q[k] = p[k] * math.exp(s)
                points.append(q)
        one = np.array([prob.residual_vector(q) for q in points])
        batch = prob.residual_vectors(points)
        assert batch.shape == one.shape == (len(points), prob.n_obs)
        scale = np.max(np.abs(one))
        assert np.array_equal(batch, one) and scale > 0
        J = jacobian_log(prob, p, free)
        ref = jacobian_one_by_one(prob, p, free)
        assert J.flags.c_contiguous
        assert np.array_equal(J, ref)


def test_profile_forward_jacobian_matches_the_sequential_loop() -> None:
    m = get_model("half4")
    meas, p, _ = _free_response("half4")
    prob = OutputErrorProblem(m, meas, cost="sse", x0="estimate")
    free = list(p)
    cost = _Cost(prob, p, free)
    u = np.full(len(free), 0.01)
    r = cost.resid(u)
    assert r is not None
    others = [0, 2, 3]
    J = _fd_jacobian(cost, u, r, others)
    assert J is not None and cost.nfev == 1 + len(others)
    ref = np.empty_like(J)
    for j, i in enumerate(others):
        up = u.copy()
        up[i] += 1e-6
        rp = cost.resid(up)
        assert rp is not None
        ref[:, j] = (rp - r) / 1e-6
    assert np.max(np.abs(J - ref)) <= 1e-12 * np.max(np.abs(ref))
    # a point out of range ends the Jacobian, counting only what was evaluated before it
    n0 = cost.nfev
    far = u.copy()
    far[1] = 40.0
    assert cost.resids([u, far, u]) is None
    assert cost.nfev == n0 + 1
