"""The models implement the seed's equations 1-7 term by term."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from suspid.models import MODELS, SuspensionModel, get_model
from suspid.simulate import simulate_states


def test_quarter1_eq1() -> None:
    m = get_model("quarter1")
    p = dict(m=250.0, c=800.0, k=9000.0)
    x, xd, y, yd = 0.03, -0.2, 0.01, 0.05
    acc = m.rhs(0.0, np.array([x, xd]), np.array([y, yd]), p)[1]
    assert np.isclose(p["m"] * acc + p["c"] * (xd - yd) + p["k"] * (x - y), 0.0)


def test_quarter2_eqs2_3() -> None:
    m = get_model("quarter2")
    p = dict(m1=275.0, k1=150000.0, c1=1120.0, m2=27.0, k2=310000.0, c2=3100.0)
    x1, x2, v1, v2, r, rd = 0.02, -0.01, 0.3, -0.4, 0.005, 0.2
    a1, a2 = m.rhs(0.0, np.array([x1, x2, v1, v2]), np.array([r, rd]), p)[2:]
    e2 = p["m1"] * a1 + p["c1"] * (v1 - v2) + p["k1"] * (x1 - x2)
    e3 = (p["m2"] * a2 + p["c1"] * (v2 - v1) + p["k1"] * (x2 - x1)
          + p["c2"] * (v2 - rd) + p["k2"] * (x2 - r))
    assert np.isclose(e2, 0.0, atol=1e-9) and np.isclose(e3, 0.0, atol=1e-9)


def test_half4_eqs4_7() -> None:
    m = get_model("half4")
    p = m.defaults()
    rng = np.random.default_rng(3)
    s = rng.standard_normal(8) * 0.05
    x, d, x1, x2, xd, dd, x1d, x2d = s
    r1, r2 = 0.01, -0.02
    acc = m.rhs(0.0, s, np.array([r1, r2, 0.0, 0.0]), p)[4:]
    a1, a2 = p["a1"], p["a2"]
    D1, D2 = x - x1 - a1 * d, x - x2 + a2 * d
    V1, V2 = xd - x1d - a1 * dd, xd - x2d + a2 * dd
    e4 = p["m"] * acc[0] + p["c1"] * V1 + p["c2"] * V2 + p["k1"] * D1 + p["k2"] * D2
    e5 = p["I"] * acc[1] - a1 * p["c1"] * V1 + a2 * p["c2"] * V2 - a1 * p["k1"] * D1 + a2 * p["k2"] * D2
    e6 = p["m1"] * acc[2] - p["c1"] * V1 + p["k3"] * (x1 - r1) - p["k1"] * D1
    e7 = p["m2"] * acc[3] - p["c2"] * V2 + p["k4"] * (x2 - r2) - p["k2"] * D2
    assert np.allclose([e4, e5, e6, e7], 0.0, atol=1e-8)


def test_models_are_stable_at_defaults() -> None:
    for name in MODELS:
        m = get_model(name)
        A, _ = m.state_space(m.defaults())
        assert np.all(np.linalg.eigvals(A).real < 0)


def _smooth_roads(m: SuspensionModel, t: np.ndarray) -> np.ndarray:
    """``[r, r_dot]`` of every road: a sum of sines in a sin^2 window (starts at rest,
    ``r_dot`` the exact derivative of ``r``)."""
    T = t[-1]
    w, wd = np.sin(np.pi * t / T) ** 2, np.pi / T * np.sin(2 * np.pi * t / T)
    rs, rds = [], []
    for j in range(len(m.roads)):
        f = np.array([0.7, 1.3, 3.1, 7.7, 13.0]) * (1 + 0.1 * j)
        a = np.array([1.0, 0.5, 0.3, 0.1, 0.05]) * 1e-2
        ph = np.arange(5.0) + j
        s = (a[:, None] * np.sin(2 * np.pi * f[:, None] * t + ph[:, None])).sum(0)
        sd = (a[:, None] * 2 * np.pi * f[:, None] * np.cos(2 * np.pi * f[:, None] * t
                                                           + ph[:, None])).sum(0)
        rs.append(s * w)
        rds.append(sd * w + s * wd)
    return np.column_stack(rs + rds)


@pytest.mark.parametrize("name", MODELS)
def test_a_twin_has_the_same_response_on_its_coordinates_only(name: str) -> None:
    """Every model's :meth:`twin`, for every set of measured coordinates: the twin's
    response equals the parameters' on those coordinates (1e-9) and not on the others,
    the twin of the twin is the original, and the rule picks exactly one of the two.
    The quarter car seen from the body is the one case with a twin."""
    m = get_model(name)
    p = m.defaults()
    t = np.arange(0.0, 5.0, 0.001)
    U = _smooth_roads(m, t)
    X = simulate_states(m, p, t, U)
    found = []
    for n in range(1, len(m.coords) + 1):
        for sub in itertools.combinations(m.coords, n):
            tw = m.twin(p, set(sub))
            if tw is None:
                continue
            found.append(sub)
            Xt = simulate_states(m, tw.params, t, U)
            for i, c in enumerate(m.coords):
                for j in (i, i + len(m.coords)):  # position and velocity
                    err = np.abs(X[:, j] - Xt[:, j]).max() / np.abs(X[:, j]).max()
                    assert bool(err < 1e-9) is (c in sub), (c, err)
            back = m.twin(tw.params, set(sub))
            assert back is not None and back.prefer is not tw.prefer
            for k, v in p.items():
                assert back.params[k] == pytest.approx(v, rel=1e-12), k
    assert found == ([("x1",)] if name == "quarter2" else [])


@pytest.mark.parametrize("name", MODELS)
def test_a_model_declares_which_coordinates_are_angles(name: str) -> None:
    # the units a CSV header may name come from here (SuspensionModel.column_units)
    model = get_model(name)
    assert model.angles is not None and set(model.angles) <= set(model.coords)
    for c in model.coords:
        unit = "rad" if c in model.angles else "m"
        assert model.column_units(c) == (unit,)
        assert model.column_units(f"{c}_dot") == (f"{unit}/s",)
        assert model.column_units(f"{c}_ddot") == (f"{unit}/s^2",)
    # the body's rotations are the angles: pitch (delta) of the half and full car, roll (phi)
    assert set(model.angles) == {"delta", "phi"} & set(model.coords)
