"""``estimator.identify.solver.minimize_log``: scipy's Nelder–Mead with restarts."""
from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from estimator.identify.solver import minimize_log


def rosen(x: np.ndarray) -> float:
    return float(np.sum(100.0 * (x[1:] - x[:-1] ** 2) ** 2 + (1 - x[:-1]) ** 2))


def test_one_run_is_scipys_nelder_mead() -> None:
    """Without restarts, ``minimize_log`` is one call of scipy's Nelder–Mead with the
    options given (``adaptive`` by default above four parameters)."""
    def cost(u: np.ndarray) -> float:
        return rosen(u + 1.0) + 1e-3

    n = 6
    sim = np.vstack([np.zeros(n)] + [0.05 * e for e in np.eye(n)])
    runs = {}
    for adaptive in (None, True, False):
        got = minimize_log(cost, np.zeros(n), maxfev=600, restarts=0, xatol=1e-4,
                           fatol=np.inf, initial_simplex=sim, adaptive=adaptive)
        ref = minimize(cost, sim[0], method="Nelder-Mead",
                       options={"initial_simplex": sim, "xatol": 1e-4, "fatol": np.inf,
                                "maxfev": 600, "adaptive": adaptive is not False})
        assert np.array_equal(got.u, ref.x) and got.nfev == ref.nfev
        assert got.final_simplex is not None
        assert np.array_equal(got.final_simplex, ref.final_simplex[0])
        runs[adaptive] = got
    assert np.array_equal(runs[None].u, runs[True].u)
    assert runs[False].nfev != runs[True].nfev


def test_restarts_reach_the_minimum_within_bounds_and_budget() -> None:
    """Restarts from the best vertex reach Rosenbrock's minimum; the budget holds over all
    runs and a bounded coordinate stays inside its bounds."""
    def cost(u: np.ndarray) -> float:
        return rosen(u + 1.0)

    for n in (2, 3, 5):
        out = minimize_log(cost, np.full(n, -0.5), maxfev=400 * n)
        assert out.converged and out.nfev <= 400 * n
        assert np.allclose(out.u, 0.0, atol=1e-4)
        assert out.final_simplex is not None and out.final_simplex.shape == (n + 1, n)
    bounded = minimize_log(cost, np.array([-0.3, 0.0]), maxfev=800, bounds=[(-0.5, -0.2), (None, None)])
    assert -0.5 <= bounded.u[0] <= -0.2


def test_no_free_parameter_is_one_evaluation() -> None:
    out = minimize_log(lambda u: 3.0, np.zeros(0))
    assert (out.fun, out.nfev, out.converged) == (3.0, 1, True)
