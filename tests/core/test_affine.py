"""One forward model: the affine pieces equal the model's matrices, and the simulator, the
identifier, the effects simulator and the node's plant give the same trajectories through
them (the EKF's use of them: ``tests/stream/test_ekf.py``)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from estimator.identify import OutputErrorProblem
from firmware_sim.plant import Plant
from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement
from suspid.models import MODELS, get_model
from suspid.simulate import simulate, simulate_ode


@pytest.mark.parametrize("name", list(MODELS))
def test_pieces_equal_the_state_space_for_any_dampers_and_springs(name: str) -> None:
    m = get_model(name)
    p = m.defaults()
    aff = m.affine(p)
    assert aff.exact and set(aff.names) == {s.name for s in m.params
                                            if s.kind in ("damping", "stiffness")}
    rng = np.random.default_rng(11)
    for _ in range(3):
        q = dict(p, **{k: p[k] * float(np.exp(rng.normal(0, 0.7))) for k in aff.names})
        assert aff.matches(q)
        A, B = aff.state_space(aff.theta(q))
        A_ref, B_ref = m.state_space(q)
        np.testing.assert_allclose(A, A_ref, rtol=0, atol=1e-12 * np.abs(A_ref).max())
        np.testing.assert_allclose(B, B_ref, rtol=0, atol=1e-12 * np.abs(B_ref).max())
    # a changed fixed parameter: the pieces do not apply (the callers use the model)
    assert not aff.matches(dict(p, **{m.params[0].name: 2 * p[m.params[0].name]}))
    # a mass is not affine: reported, not silently wrong
    assert not m.affine(p, [m.params[0].name]).exact


@pytest.mark.parametrize("name", list(MODELS))
def test_simulate_through_the_pieces_equals_the_model(name: str) -> None:
    m = get_model(name)
    p = m.defaults()
    q = {k: (v * 0.7 if m.spec(k).kind == "damping" else v) for k, v in p.items()}
    t, road, x0 = make_scenario(m, "bump", duration=1.0, fs=500.0)
    ref = simulate(m, q, t, road, x0)
    got = simulate(m, q, t, road, x0, affine=m.affine(p))
    for c in m.channels:
        # roll stays ~0 on a bump over both tracks: scale by the car, not by the channel
        np.testing.assert_allclose(got[c], ref[c], rtol=0, atol=1e-10 * np.abs(ref[c]).max() + 1e-12)


def test_plant_with_a_wearing_damper_follows_the_piecewise_simulation() -> None:
    m = get_model("full7")
    p0 = m.defaults()
    t, road, x0 = make_scenario(m, "iso8608", duration=2.0, fs=500.0, v_kmh=40)

    def params(tt: float) -> dict[str, float]:
        return dict(p0, c3=p0["c3"] * (1.0 - 0.2 * tt))

    plant = Plant(m, params, t, road, x0, chunk_s=0.5)
    got = np.array([plant.sample(k)["x3"] for k in range(t.size)])
    # reference: the model's own matrices, chunk by chunk
    ref = np.empty(t.size)
    x = x0
    for k in range(0, t.size - 1, plant.chunk):
        e = min(t.size, k + plant.chunk + 1)
        out = simulate(m, params(float(t[k])), t[k:e], {n: v[k:e] for n, v in road.items()}, x)
        ref[k:e] = out["x3"]
        x = np.array([out[c][-1] for c in m.coords] + [out[f"{c}_dot"][-1] for c in m.coords])
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    assert plant.affine.exact and plant.affine.matches(params(1.0))


@pytest.mark.parametrize("name", list(MODELS))
def test_accelerations_slopes_and_mass_inverse_of_the_pieces(name: str) -> None:
    m = get_model(name)
    p = m.defaults()
    aff = m.affine(p)
    nq, nr = len(m.coords), len(m.roads)
    rng = np.random.default_rng(3)
    q = dict(p, **{k: p[k] * float(np.exp(rng.normal(0, 0.5))) for k in aff.names})
    th = aff.theta(q)
    X = rng.normal(size=(5, 2 * nq))
    U = rng.normal(size=(5, 2 * nr))
    ref = m.accelerations(X, U, q)
    np.testing.assert_allclose(aff.accelerations(X, U, th), ref, rtol=0,
                               atol=1e-12 * np.abs(ref).max())
    # the inverse mass matrix of the model at the base, and the model's own
    M = m.matrices(p)[0]
    assert aff.Minv is not None
    np.testing.assert_allclose(aff.Minv @ M, np.eye(nq), rtol=0, atol=1e-12)
    np.testing.assert_allclose(m.mass_inverse(q), aff.Minv, rtol=1e-13, atol=0)


@pytest.mark.parametrize("uniform", [True, False], ids=["modal", "general"])
@pytest.mark.parametrize("name", list(MODELS))
def test_identifier_predicts_through_the_pieces_as_dop853_of_the_rhs(name: str, uniform: bool) -> None:
    m = get_model(name)
    p = m.defaults()
    t, road, _ = make_scenario(m, "bump", duration=0.4, fs=500.0, params=p, t0=0.05)
    x0 = 0.2 * m.initial_state()
    if not uniform:  # a jittered grid: the general (stepwise) path
        t = t + np.random.default_rng(1).uniform(-2e-4, 2e-4, t.size) * (np.arange(t.size) > 0)
    q = {k: (v * 0.7 if m.spec(k).kind == "damping" else v * 1.2 if m.spec(k).kind == "stiffness"
             else v) for k, v in p.items()}
    ref = simulate_ode(m, q, t, road, x0)
    meas = Measurement(t=t, road=road, measured={c: ref[c] for c in m.channels}, source="dop853")
    pr = OutputErrorProblem(m, meas, cost="frobenius", x0=x0)
    assert pr.affine is None
    pred = pr.predict(p)  # the first prediction builds the pieces at p
    assert pr.affine is not None and pr.affine.exact and pr.affine.matches(q)
    pred = pr.predict(q)
    for j, c in enumerate(pr.channels):
        scale = np.abs(ref[c]).max() + np.abs(ref[m.coords[0]]).max() * 1e-3
        np.testing.assert_allclose(pred.Y[:, j], ref[c], rtol=0, atol=1e-7 * scale, err_msg=c)
    # the prediction really comes from the pieces: other pieces, another prediction
    pr.affine = replace(pr.affine, dAB=pr.affine.dAB * 1.01)
    assert np.max(np.abs(pr.predict(q).Y - pred.Y)) > 1e-4 * np.abs(pred.Y).max()
    # a changed mass: the pieces do not apply, the model itself predicts
    mass = next(s.name for s in m.params if s.kind == "mass")
    q2 = dict(q, **{mass: 1.1 * q[mass]})
    assert not pr.affine.matches(q2)
    ref2 = simulate_ode(m, q2, t, road, x0)
    got2 = pr.predict(q2).Y
    for j, c in enumerate(pr.channels):
        scale = np.abs(ref2[c]).max() + np.abs(ref2[m.coords[0]]).max() * 1e-3
        np.testing.assert_allclose(got2[:, j], ref2[c], rtol=0, atol=1e-7 * scale, err_msg=c)
