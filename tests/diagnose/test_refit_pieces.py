"""The refits simulate through the forward model's affine pieces, built once: same numbers as the model."""
from __future__ import annotations

import numpy as np
import pytest

from estimator.diagnose.refit import PhysicalRefit, SensorRefit, all_channels, forward_pieces
from estimator.identify import OutputErrorProblem
from suspid.effects import parse_effect
from suspid.models import get_model
from suspid.nlsim import simulate_effects
from suspid.simulate import simulate_states

from .conftest import make_measurement


def _problem(model: str = "quarter2") -> OutputErrorProblem:
    meas = make_measurement(["coulomb_friction:F=80"], "bump", model=model)
    return OutputErrorProblem(get_model(model), meas, cost="sse", x0="rest")


@pytest.mark.parametrize("model, effect", [
    ("quarter2", "coulomb_friction:F=80"), ("quarter2", "asymmetric_damping:c_rebound=1600,c_compression=640"),
    ("half4", "quadratic_damping:c_quad=1500")])
def test_physical_refit_simulates_as_the_model(model: str, effect: str) -> None:
    pr = _problem(model)
    m = pr.model
    base = m.defaults()
    free = [s.name for s in m.params if s.kind in ("damping", "stiffness")]
    eff = parse_effect(effect)
    x0 = np.zeros(m.n_states)
    rf = PhysicalRefit(pr, base, free, eff, x0)
    # a damper and a spring moved 30 % away from the base: the pieces apply
    theta = {k: base[k] * (1.3 if i % 2 else 0.7) for i, k in enumerate(rf.base_free)}
    theta.update({k: float(eff.values[k]) for k in rf.eff_names})
    p, e = rf.split(theta)
    assert rf.affine.exact and rf.affine.matches(p) and p != base
    got = rf.simulate(p, e, x0)
    ref = simulate_effects(m, p, [e], pr.t, U=pr.U, x0=x0, substeps=rf.substeps)
    for c in m.channels:
        scale = float(np.max(np.abs(ref[c]))) + 1e-300
        assert np.max(np.abs(got[c] - ref[c])) <= 1e-9 * scale, c


def test_a_free_mass_falls_back_to_the_model() -> None:
    pr = _problem()
    m = pr.model
    base = m.defaults()
    eff = parse_effect("coulomb_friction:F=80")
    x0 = np.zeros(m.n_states)
    rf = PhysicalRefit(pr, base, ["m1", "c1", "k1"], eff, x0)
    assert not rf.affine.exact
    p = dict(base, m1=1.2 * base["m1"], c1=0.8 * base["c1"])
    assert not rf.affine.matches(p)
    got = rf.simulate(p, eff, x0)
    ref = simulate_effects(m, p, [eff], pr.t, U=pr.U, x0=x0, substeps=rf.substeps)
    for c in m.channels:
        np.testing.assert_array_equal(got[c], ref[c])


def test_the_problem_s_own_pieces_are_shared_when_they_apply() -> None:
    pr = _problem()
    base = pr.model.defaults()
    own = pr.pieces(base)
    assert forward_pieces(pr, base) is own
    assert forward_pieces(pr, base, ["c1", "k1"]) is own
    # other masses, or a mass among the moving parameters: new pieces
    assert forward_pieces(pr, dict(base, m1=base["m1"] + 1.0)) is not own
    assert forward_pieces(pr, base, ["m1", "c1"]) is not own
    sr = SensorRefit(pr, base, ["c1", "k1"], parse_effect("sensor_offset:channel=x1,offset=0.001"))
    assert sr.affine is own and sr.sub_problem(None).affine is own


def test_all_channels_equals_the_model_simulation() -> None:
    pr = _problem()
    m = pr.model
    p = dict(m.defaults(), c1=1100.0, k2=2.1e5)
    x0 = np.array([0.01, 0.0, 0.0, 0.1])
    pr.pieces(m.defaults())
    got = all_channels(pr, p, x0)
    X = simulate_states(m, p, pr.t, pr.U, x0)
    A, B = m.state_space(p)
    nq = len(m.coords)
    acc = X @ A[nq:].T + pr.U @ B[nq:].T
    for i, c in enumerate(m.coords):
        for name, ref in ((c, X[:, i]), (f"{c}_dot", X[:, nq + i]), (f"{c}_ddot", acc[:, i])):
            scale = float(np.max(np.abs(ref))) + 1e-300
            assert np.max(np.abs(got[name] - ref)) <= 1e-9 * scale, name
