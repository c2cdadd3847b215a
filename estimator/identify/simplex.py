"""Nelder–Mead downhill simplex, a scipy-free replica of scipy's implementation.

:func:`nelder_mead` reproduces ``scipy.optimize.minimize(method="Nelder-Mead")`` of scipy
1.17.1 (``scipy.optimize._optimize._minimize_neldermead``) operation for operation: the
same initial simplex (5 % of each non-zero coordinate, 0.00025 for a zero one), the same
bounds handling (clipping of the start, the simplex and every trial point; reflection of
vertices above an upper bound), the same (adaptive) coefficients, sort, termination tests,
defaults and evaluation budget, including what happens when the budget runs out in the
middle of an iteration or of a shrink. Iterates, ``nfev``, ``nit``, the final simplex and
``x`` are bit-identical to scipy's for the same inputs.

It exists so that ``suspid monitor`` does not import ``scipy.optimize`` only to run a simplex
on two to four parameters: 0.13-0.19 s of every process start on top of ``scipy.linalg``,
which the monitor needs anyway (docs/monitoring.md, benchmarks).

The algorithm below is ported from SciPy and stays under SciPy's licence:

    Copyright (c) 2001-2002 Enthought, Inc. 2003, SciPy Developers.
    All rights reserved.

    Redistribution and use in source and binary forms, with or without modification, are
    permitted provided that the following conditions are met:

    1. Redistributions of source code must retain the above copyright notice, this list of
       conditions and the following disclaimer.
    2. Redistributions in binary form must reproduce the above copyright notice, this list
       of conditions and the following disclaimer in the documentation and/or other
       materials provided with the distribution.
    3. Neither the name of the copyright holder nor the names of its contributors may be
       used to endorse or promote products derived from this software without specific
       prior written permission.

    THIS SOFTWARE IS PROVIDED BY THE COPYRIGHT HOLDERS AND CONTRIBUTORS "AS IS" AND ANY
    EXPRESS OR IMPLIED WARRANTIES, INCLUDING, BUT NOT LIMITED TO, THE IMPLIED WARRANTIES OF
    MERCHANTABILITY AND FITNESS FOR A PARTICULAR PURPOSE ARE DISCLAIMED. IN NO EVENT SHALL
    THE COPYRIGHT OWNER OR CONTRIBUTORS BE LIABLE FOR ANY DIRECT, INDIRECT, INCIDENTAL,
    SPECIAL, EXEMPLARY, OR CONSEQUENTIAL DAMAGES (INCLUDING, BUT NOT LIMITED TO,
    PROCUREMENT OF SUBSTITUTE GOODS OR SERVICES; LOSS OF USE, DATA, OR PROFITS; OR BUSINESS
    INTERRUPTION) HOWEVER CAUSED AND ON ANY THEORY OF LIABILITY, WHETHER IN CONTRACT,
    STRICT LIABILITY, OR TORT (INCLUDING NEGLIGENCE OR OTHERWISE) ARISING IN ANY WAY OUT OF
    THE USE OF THIS SOFTWARE, EVEN IF ADVISED OF THE POSSIBILITY OF SUCH DAMAGE.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any, Callable, Sequence, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["SimplexResult", "SimplexWarning", "nelder_mead"]

_MSG_SUCCESS = "Optimization terminated successfully."
_MSG_MAXFEV = "Maximum number of function evaluations has been exceeded."
_MSG_MAXITER = "Maximum number of iterations has been exceeded."


class SimplexWarning(UserWarning):
    """Warning of :func:`nelder_mead` (scipy raises ``OptimizeWarning`` in its place)."""


class _MaxFevReached(Exception):
    """Internal: the evaluation budget is spent (scipy's ``_MaxFuncCallError``)."""


@dataclass
class SimplexResult:
    """Outcome of :func:`nelder_mead`, with the fields of scipy's ``OptimizeResult``.

    Attributes
    ----------
    x : ndarray
        Best vertex (units of ``x0``).
    fun : float
        Smallest objective value in the final simplex (units of ``fun``).
    nfev : int
        Number of objective evaluations.
    nit : int
        Number of iterations (counted as scipy does, starting at 1).
    status : int
        0 converged, 1 evaluation budget (``maxfev``) spent, 2 ``maxiter`` reached.
    success : bool
        ``status == 0``.
    message : str
        scipy's message for ``status``.
    final_simplex : tuple of ndarray
        ``(sim, fsim)``: vertices, shape ``(N + 1, N)``, sorted by their objective values
        ``fsim``, shape ``(N + 1,)``.
    """

    x: NDArray[Any]
    fun: float
    nfev: int
    nit: int
    status: int
    success: bool
    message: str
    final_simplex: tuple[NDArray[Any], NDArray[np.float64]]


def _scalar(v: Any) -> Any:
    """``v.item()`` for an ndarray, ``v`` otherwise (scipy's ``_arr_to_scalar``)."""
    return v.item() if isinstance(v, np.ndarray) else v


def _bounds_arrays(bounds: Any, x0: NDArray[Any]) -> tuple[NDArray[Any], NDArray[Any]]:
    """Lower and upper bound arrays broadcast to ``x0.shape`` (scipy's standardisation)."""
    if hasattr(bounds, "lb") and hasattr(bounds, "ub"):
        lb, ub = np.broadcast_arrays(np.atleast_1d(bounds.lb), np.atleast_1d(bounds.ub))
    else:
        lo, hi = zip(*bounds)
        lb = np.array([float(_scalar(v)) if v is not None else -np.inf for v in lo])
        ub = np.array([float(_scalar(v)) if v is not None else np.inf for v in hi])
    if np.any(ub < lb):
        raise ValueError("An upper bound is less than the corresponding lower bound.")
    try:
        lb = np.broadcast_to(lb, x0.shape)
        ub = np.broadcast_to(ub, x0.shape)
    except ValueError as e:
        raise ValueError("The number of bounds is not compatible with the length of "
                         "`x0`.") from e
    return lb, ub


def nelder_mead(fun: Callable[[NDArray[Any]], Any], x0: ArrayLike, *,
                initial_simplex: ArrayLike | None = None, xatol: float = 1e-4,
                fatol: float = 1e-4, maxiter: float | None = None,
                maxfev: float | None = None, adaptive: bool = False,
                bounds: Sequence[tuple[float | None, float | None]] | Any | None = None,
                ) -> SimplexResult:
    """Minimise ``fun(x)`` by the Nelder–Mead simplex exactly as scipy 1.17.1 does.

    Equivalent to ``scipy.optimize.minimize(fun, x0, method="Nelder-Mead", bounds=bounds,
    options={...})`` with the same options, bit for bit.

    Parameters
    ----------
    fun : callable
        Objective ``fun(x) -> float`` (any units); it receives a copy of the vertex. A
        one-element array is accepted as a scalar. ``inf`` marks an infeasible point.
    x0 : array_like, shape (N,)
        Start (any units). Ignored for the simplex when ``initial_simplex`` is given, but
        still checked against the bounds.
    initial_simplex : array_like, shape (N + 1, N), optional
        Initial vertices. Default: ``x0`` and ``N`` copies with one coordinate scaled by
        1.05 (or set to 0.00025 if it is zero).
    xatol : float
        Convergence when every vertex is within ``xatol`` of the best one in every
        coordinate (units of ``x``) ...
    fatol : float
        ... and every vertex's value is within ``fatol`` of the best one (units of ``fun``).
    maxiter : float, optional
        Maximum number of iterations (``inf`` allowed).
    maxfev : float, optional
        Maximum number of objective evaluations (``inf`` allowed). If neither limit is
        given both are ``200 N``; if only one is, the other is unlimited (or ``200 N``
        when the given one is ``inf``).
    adaptive : bool
        Use the dimension-dependent coefficients of Gao & Han (2012) instead of the
        standard 1, 2, 0.5, 0.5.
    bounds : sequence of (float or None, float or None), or object with ``lb``, ``ub``
        Bounds per coordinate (``None`` or ``±inf`` means unbounded), or an object with
        array attributes ``lb`` and ``ub`` such as ``scipy.optimize.Bounds``. The start,
        the simplex and every trial point are clipped to them; a start outside them
        raises a :class:`SimplexWarning`.

    Returns
    -------
    SimplexResult
        Best vertex, value, counters, status and the final simplex.

    Raises
    ------
    ValueError
        Malformed ``x0``, ``initial_simplex`` or ``bounds``, or an objective that does not
        return a scalar.
    """
    x0 = np.atleast_1d(np.asarray(x0))
    if x0.ndim != 1:
        raise ValueError("'x0' must only have one dimension.")
    if x0.dtype.kind in np.typecodes["AllInteger"]:
        x0 = np.asarray(x0, dtype=float)
    lower_bound = upper_bound = None
    if bounds is not None:
        lower_bound, upper_bound = _bounds_arrays(bounds, x0)
    maxfun = maxfev

    # --- from here on: scipy's _minimize_neldermead, statement for statement ---
    x0 = x0.flatten()
    dtype = x0.dtype if np.issubdtype(x0.dtype, np.inexact) else np.float64
    x0 = np.asarray(x0, dtype=dtype)

    if adaptive:
        dim = float(len(x0))
        rho: float = 1
        chi: float = 1 + 2 / dim
        psi = 0.75 - 1 / (2 * dim)
        sigma = 1 - 1 / dim
    else:
        rho = 1
        chi = 2
        psi = 0.5
        sigma = 0.5

    nonzdelt = 0.05
    zdelt = 0.00025

    if lower_bound is not None:
        if (lower_bound > upper_bound).any():
            raise ValueError("Nelder Mead - one of the lower bounds "
                             "is greater than an upper bound.")
        if np.any(lower_bound > x0) or np.any(x0 > upper_bound):
            warnings.warn("Initial guess is not within the specified bounds",
                          SimplexWarning, stacklevel=2)
        # numpy's stubs type np.clip of an ndarray of unknown dtype as Any
        x0 = cast("NDArray[Any]", np.clip(x0, lower_bound, upper_bound))

    if initial_simplex is None:
        N = len(x0)
        sim = np.empty((N + 1, N), dtype=x0.dtype)
        sim[0] = x0
        for k in range(N):
            y = np.array(x0, copy=True)
            if y[k] != 0:
                y[k] = (1 + nonzdelt) * y[k]
            else:
                y[k] = zdelt
            sim[k + 1] = y
    else:
        sim = np.atleast_2d(initial_simplex).copy()
        dtype = sim.dtype if np.issubdtype(sim.dtype, np.inexact) else np.float64
        sim = np.asarray(sim, dtype=dtype)
        if sim.ndim != 2 or sim.shape[0] != sim.shape[1] + 1:
            raise ValueError("`initial_simplex` should be an array of shape (N+1,N)")
        if len(x0) != sim.shape[1]:
            raise ValueError("Size of `initial_simplex` is not consistent with `x0`")
        N = sim.shape[1]

    # scipy's `if maxiter is None and maxfun is None: ... elif maxiter is None: ... elif
    # maxfun is None: ...`, nested so that the type checker sees neither stays None
    if maxiter is None:
        if maxfun is None:
            maxiter = N * 200
            maxfun = N * 200
        else:
            maxiter = N * 200 if maxfun == np.inf else np.inf
    elif maxfun is None:
        maxfun = N * 200 if maxiter == np.inf else np.inf

    if lower_bound is not None and upper_bound is not None:  # both are set together
        # reflect vertices above an upper bound into the interior, then clip
        msk = sim > upper_bound
        sim = np.where(msk, 2 * upper_bound - sim, sim)
        sim = np.clip(sim, lower_bound, upper_bound)

    one2np1 = list(range(1, N + 1))
    fsim = np.full((N + 1,), np.inf, dtype=float)

    ncalls = 0
    copy = np.copy
    isscalar = np.isscalar

    def func(x: NDArray[Any]) -> Any:
        # scipy's _wrap_scalar_function_maxfun_validation
        nonlocal ncalls
        if ncalls >= maxfun:
            raise _MaxFevReached
        ncalls += 1
        fx = fun(copy(x))
        if not isscalar(fx):
            try:
                fx = np.asarray(fx).item()
            except (TypeError, ValueError) as e:
                raise ValueError("The user-provided objective function "
                                 "must return a scalar value.") from e
        return fx

    try:
        for k in range(N + 1):
            fsim[k] = func(sim[k])
    except _MaxFevReached:
        pass
    finally:
        ind = np.argsort(fsim)
        sim = np.take(sim, ind, 0)
        fsim = np.take(fsim, ind, 0)

    ind = np.argsort(fsim)
    fsim = np.take(fsim, ind, 0)
    sim = np.take(sim, ind, 0)

    iterations = 1
    bounded = lower_bound is not None
    clip = np.clip

    while ncalls < maxfun and iterations < maxiter:
        try:
            if (np.max(np.ravel(np.abs(sim[1:] - sim[0]))) <= xatol and
                    np.max(np.abs(fsim[0] - fsim[1:])) <= fatol):
                break

            xbar = np.add.reduce(sim[:-1], 0) / N
            xr = (1 + rho) * xbar - rho * sim[-1]
            if bounded:
                xr = clip(xr, lower_bound, upper_bound)
            fxr = func(xr)
            doshrink = 0

            if fxr < fsim[0]:
                xe = (1 + rho * chi) * xbar - rho * chi * sim[-1]
                if bounded:
                    xe = clip(xe, lower_bound, upper_bound)
                fxe = func(xe)

                if fxe < fxr:
                    sim[-1] = xe
                    fsim[-1] = fxe
                else:
                    sim[-1] = xr
                    fsim[-1] = fxr
            else:  # fsim[0] <= fxr
                if fxr < fsim[-2]:
                    sim[-1] = xr
                    fsim[-1] = fxr
                else:  # fxr >= fsim[-2]
                    if fxr < fsim[-1]:
                        # outside contraction
                        xc = (1 + psi * rho) * xbar - psi * rho * sim[-1]
                        if bounded:
                            xc = clip(xc, lower_bound, upper_bound)
                        fxc = func(xc)

                        if fxc <= fxr:
                            sim[-1] = xc
                            fsim[-1] = fxc
                        else:
                            doshrink = 1
                    else:
                        # inside contraction
                        xcc = (1 - psi) * xbar + psi * sim[-1]
                        if bounded:
                            xcc = clip(xcc, lower_bound, upper_bound)
                        fxcc = func(xcc)

                        if fxcc < fsim[-1]:
                            sim[-1] = xcc
                            fsim[-1] = fxcc
                        else:
                            doshrink = 1

                    if doshrink:
                        # a vertex is moved before its evaluation: when the budget runs
                        # out here it keeps its new position and its old value (as scipy)
                        for j in one2np1:
                            sim[j] = sim[0] + sigma * (sim[j] - sim[0])
                            if bounded:
                                sim[j] = clip(sim[j], lower_bound, upper_bound)
                            fsim[j] = func(sim[j])
            iterations += 1
        except _MaxFevReached:
            pass
        ind = np.argsort(fsim)
        sim = np.take(sim, ind, 0)
        fsim = np.take(fsim, ind, 0)

    x = sim[0]
    fval = np.min(fsim)

    if ncalls >= maxfun:
        status, msg = 1, _MSG_MAXFEV
    elif iterations >= maxiter:
        status, msg = 2, _MSG_MAXITER
    else:
        status, msg = 0, _MSG_SUCCESS
    return SimplexResult(x=x, fun=float(fval), nfev=ncalls, nit=iterations, status=status,
                         success=status == 0, message=msg, final_simplex=(sim, fsim))
