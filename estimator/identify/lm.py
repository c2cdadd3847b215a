"""Levenberg–Marquardt on a residual vector within a hard evaluation budget.

scipy's ``least_squares(method="lm")`` leaves its finite-difference Jacobians out of
``max_nfev``; :func:`lm_within` counts every call of the residual function and stops
when the budget is spent, returning the best point evaluated.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from suspid.models.base import FloatArray


class _Spent(Exception):
    """Raised inside the residual function when the evaluation budget is spent."""


@dataclass
class LMOutcome:
    """Outcome of :func:`lm_within`: the solution (or best point evaluated) ``x``, its ``|r|^2``,
    every evaluation made and whether the budget cut the search short.
    """

    x: FloatArray
    fun: float
    nfev: int
    stopped: bool


def lm_within(fun: Callable[[FloatArray], FloatArray], x0: FloatArray, max_evals: int | None,
              max_nfev: int, **options: Any) -> LMOutcome:
    """Minimise ``|fun(x)|^2`` (``fun``: a residual vector of constant length) by
    Levenberg–Marquardt from ``x0`` with at most ``max_evals`` calls of ``fun``, Jacobians
    included (None: scipy's iteration budget ``max_nfev`` only); ``options`` go to
    ``scipy.optimize.least_squares``, whose ``ValueError`` and ``LinAlgError`` pass through.
    """
    # lazy: scipy.optimize costs the monitor's start time and only the polish needs it
    from scipy.optimize import least_squares  # noqa: PLC0415

    best: dict[str, Any] = {"x": np.asarray(x0, dtype=float), "f": np.inf}
    count = {"n": 0}

    def counted(x: FloatArray) -> FloatArray:
        if max_evals is not None and count["n"] >= max_evals:
            raise _Spent
        count["n"] += 1
        r = np.asarray(fun(x), dtype=float)
        f = float(r @ r)
        if f < best["f"]:
            best["x"], best["f"] = np.array(x, dtype=float), f
        return r

    try:
        sol = least_squares(counted, x0, method="lm", max_nfev=max_nfev, **options)
    except _Spent:
        return LMOutcome(best["x"], float(best["f"]), count["n"], True)
    return LMOutcome(np.asarray(sol.x, dtype=float), float(2.0 * sol.cost), count["n"], False)


__all__ = ["LMOutcome", "lm_within"]
