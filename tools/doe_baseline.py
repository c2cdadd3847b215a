"""A paper-faithful port of the seed's MATLAB tool (for benchmarks and ablations).

* ``ode45``: :func:`scipy.integrate.solve_ivp` with RK45 (Dormand–Prince 5(4), the same
  pair as MATLAB's ode45) at ode45's default tolerances RelTol = 1e-3, AbsTol = 1e-6,
  output at the sample times (``t_eval``, ode45's ``tspan`` vector);
* ``fminsearch``: :func:`scipy.optimize.minimize` Nelder–Mead in the raw parameters with
  MATLAB's defaults: initial simplex 5 % of each start value (0.00025 for zeros — also
  scipy's default), TolX = TolFun = 1e-4 (absolute, as in fminsearch), MaxFunEvals =
  MaxIter = 200 x the number of unknowns, the non-adaptive coefficients;
* the seed's costs on the raw SI signals: ``sse`` = sum of squared position differences,
  ``frobenius`` = Frobenius norm of the state-difference matrix.
"""
from __future__ import annotations

from typing import Callable, Mapping

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import OptimizeResult, minimize

from suspid.models import SuspensionModel
from suspid.models.base import FloatArray

#: MATLAB ode45 defaults
ODE45_RTOL = 1e-3
ODE45_ATOL = 1e-6
#: MATLAB fminsearch defaults
FMIN_TOLX = 1e-4
FMIN_TOLFUN = 1e-4


def ode45(model: SuspensionModel, params: Mapping[str, float], t: FloatArray, x0: FloatArray,
          road_fn: Callable[[float], FloatArray] | None = None) -> FloatArray:
    """States ``(N, n)`` at ``t`` from RK45 at ode45's default tolerances.

    ``road_fn(t) -> [r..., r_dot...]`` gives the road input continuously (the seed sets it
    "programmatically in the model"); ``None`` means no road.
    """
    nu = 2 * len(model.roads)
    zero = np.zeros(nu)

    def f(tt: float, x: FloatArray) -> FloatArray:
        return model.rhs(tt, x, road_fn(tt) if road_fn is not None else zero, params)

    sol = solve_ivp(f, (float(t[0]), float(t[-1])), np.asarray(x0, dtype=float), method="RK45",
                    rtol=ODE45_RTOL, atol=ODE45_ATOL, t_eval=t)
    if not sol.success or sol.y.shape[1] != t.size:
        return np.full((t.size, model.n_states), np.nan)
    return sol.y.T


def seed_cost(model: SuspensionModel, Y: FloatArray, Yhat: FloatArray, cost: str) -> float:
    """The seed's cost between state matrices ``Y`` and ``Yhat`` (N, n), raw SI units."""
    nq = len(model.coords)
    if cost == "sse":
        d = Y[:, :nq] - Yhat[:, :nq]
        return float(np.sum(d * d))
    return float(np.linalg.norm(Y - Yhat))


def fminsearch(fun: Callable[[FloatArray], float], x0: FloatArray,
               maxfev: int | None = None) -> OptimizeResult:
    """Nelder–Mead with MATLAB fminsearch's default options (see module docstring)."""
    n = int(np.size(x0))
    budget = 200 * n if maxfev is None else maxfev
    return minimize(fun, np.asarray(x0, dtype=float), method="Nelder-Mead",
                    options={"xatol": FMIN_TOLX, "fatol": FMIN_TOLFUN, "maxiter": budget,
                             "maxfev": budget, "adaptive": False})


def seed_identify(model: SuspensionModel, Y: FloatArray, t: FloatArray, x0: FloatArray,
                  truth_fixed: Mapping[str, float], start: Mapping[str, float], cost: str,
                  simulate_states: Callable[[Mapping[str, float]], FloatArray],
                  maxfev: int | None = None) -> tuple[dict[str, float], OptimizeResult]:
    """Identify the ``start`` parameters the seed's way (raw coordinates, fminsearch).

    Parameters
    ----------
    Y : ndarray (N, n)
        Target state matrix (positions then velocities, SI).
    truth_fixed : mapping
        Known parameters (held fixed, the seed's "global variables").
    start : mapping
        Free parameters and their starting values.
    simulate_states : callable
        ``params -> (N, n)`` states (e.g. :func:`ode45`, or the exact simulator).

    Returns
    -------
    params : dict
        Every parameter at the answer.
    result : OptimizeResult
        fminsearch's raw outcome (``nfev``, ``status``).
    """
    names = list(start)

    def full(theta: FloatArray) -> dict[str, float]:
        p = dict(truth_fixed)
        p.update(zip(names, (float(v) for v in theta)))
        return p

    def fun(theta: FloatArray) -> float:
        if np.any(theta <= 0):
            return float("inf")
        Yhat = simulate_states(full(theta))
        v = seed_cost(model, Y, Yhat, cost)
        return v if np.isfinite(v) else float("inf")

    res = fminsearch(fun, np.array([start[k] for k in names]), maxfev)
    return full(res.x), res
