"""Levenberg–Marquardt on a residual vector within a hard evaluation budget.

scipy's ``least_squares(method="lm")`` counts in ``nfev`` and bounds by ``max_nfev`` only
the evaluations of its iterates: since scipy 1.17 the finite-difference Jacobians (``n``
evaluations each, one more at the end) are outside both, so a polish given 10
evaluations of a five-parameter fit made 61. :func:`lm_within` counts every call of the
residual function itself and stops the search when the budget is spent, returning the
best point it evaluated.
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
    """Outcome of :func:`lm_within`.

    ``x`` is the solution (or, when the budget stopped the search, the best point
    evaluated), ``fun`` its ``|r|^2``, ``nfev`` every evaluation made (Jacobians
    included), ``stopped`` whether the budget cut the search short.
    """

    x: FloatArray
    fun: float
    nfev: int
    stopped: bool


def lm_within(fun: Callable[[FloatArray], FloatArray], x0: FloatArray, max_evals: int | None,
              max_nfev: int, **options: Any) -> LMOutcome:
    """Minimise ``|fun(x)|^2`` by Levenberg–Marquardt with at most ``max_evals`` calls.

    Parameters
    ----------
    fun : callable
        Residual vector of ``x`` (constant length).
    x0 : ndarray
        Start.
    max_evals : int or None
        Most calls of ``fun`` in all, the finite-difference Jacobians included (None: no
        limit beyond scipy's own ``max_nfev``).
    max_nfev : int
        scipy's iteration budget (evaluations of its iterates).
    **options
        Further ``scipy.optimize.least_squares`` options (tolerances, ``diff_step``, ...).

    Returns
    -------
    LMOutcome

    Raises
    ------
    ValueError, numpy.linalg.LinAlgError
        As ``least_squares`` raises them (the caller decides what a failed polish means).
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
