"""The lean small-matrix linear algebra equals numpy's public functions bit for bit."""
from __future__ import annotations

import numpy as np

from suspid import smalllinalg
from suspid.models import get_model
from suspid.simulate import state_matrices


def _state_matrices() -> list[np.ndarray]:
    out = []
    rng = np.random.default_rng(3)
    for name in ("quarter1", "quarter2", "half4", "full7"):
        m = get_model(name)
        p0 = m.defaults()
        for _ in range(3):
            p = {k: v * float(np.exp(rng.normal(0.0, 0.5))) for k, v in p0.items()}
            out.append(state_matrices(m, p)[0])
    # real eigenvalues only (an overdamped oscillator) and a random matrix
    out.append(np.array([[0.0, 1.0], [-1.0, -5.0]]))
    out.append(rng.standard_normal((6, 6)))
    return out


def test_eig_and_inv_equal_numpy_bit_for_bit() -> None:
    for A in _state_matrices():
        got = smalllinalg.eig(A)
        assert got is not None
        lam, V = got
        ref_lam, ref_V = np.linalg.eig(A)
        assert lam.dtype == ref_lam.dtype and V.dtype == ref_V.dtype
        assert np.array_equal(lam, ref_lam) and np.array_equal(V, ref_V)
        assert np.array_equal(smalllinalg.inv(V), np.linalg.inv(ref_V))


def test_solve_and_cond_equal_numpy_bit_for_bit() -> None:
    rng = np.random.default_rng(4)
    for n in (2, 5, 8, 14):
        G = rng.standard_normal((n, n))
        G = G @ G.T + 1e-3 * np.eye(n)
        b = rng.standard_normal(n)
        assert np.array_equal(smalllinalg.solve(G, b), np.linalg.solve(G, b))
        assert smalllinalg.cond2(G) == float(np.linalg.cond(G))


def test_failures_give_none_nan_or_inf_where_numpy_raises() -> None:
    assert smalllinalg.eig(np.array([[np.nan, 1.0], [0.0, 1.0]])) is None
    assert smalllinalg.eig(np.array([[np.inf, 1.0], [0.0, 1.0]])) is None
    S = np.array([[1.0, 2.0], [2.0, 4.0]])
    assert np.isnan(smalllinalg.inv(S)).any()
    assert np.isnan(smalllinalg.solve(S, np.ones(2))).any()
    assert smalllinalg.cond2(np.zeros((3, 3))) == float("inf")
    assert smalllinalg.cond2(S) > 1e15


def test_stacks_equal_one_by_one() -> None:
    mats = [A for A in _state_matrices() if A.shape == (8, 8)]
    assert len(mats) == 3
    lam, V = smalllinalg.eig(np.stack(mats)) or (None, None)
    assert lam is not None and V is not None
    Vinv = smalllinalg.inv(V)
    for i, A in enumerate(mats):
        ref_lam, ref_V = np.linalg.eig(A)
        assert np.array_equal(lam[i], ref_lam) and np.array_equal(V[i], ref_V)
        assert np.array_equal(Vinv[i], np.linalg.inv(ref_V))
