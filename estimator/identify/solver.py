"""The solver: Nelder–Mead identification in log coordinates with restarts and a polish.

suspid optimises ``u = log(theta / theta_start)`` with scipy's Nelder–Mead, so a step of
0.1 is a 10 % change of any parameter whatever its scale, and restarts from the best
vertex with a smaller simplex until the cost no longer improves. The ``final_simplex``
of every run is kept so a sliding window can warm-start from it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np
from scipy.optimize import minimize

from estimator.identify.identifiability import assess
from estimator.identify.lm import lm_within
from estimator.identify.params import Parameters
from estimator.identify.problem import OutputErrorProblem
from estimator.identify.result import IdentResult
from suspid.models.base import FloatArray
from suspid.simulate import outputs, road_matrix, simulate_states


#: relative standard error above which a free parameter counts as not determined
UNDETERMINED = 1.0
#: evaluations per free parameter of each start of a fit without ``maxfev`` (its runs,
#: polish and finishing Nelder-Mead together)
DEFAULT_MAXFEV = 1000
#: relative difference of two costs (normalised) within which a further start of
#: :func:`fit` reached the same minimum as the best so far
SAME_COST = 1e-3


def too_little_data(problem: OutputErrorProblem, n_free: int, n_extra: int = 0) -> str | None:
    """Why the record cannot give estimates of ``n_free`` parameters: the warning naming the
    counts and the remedy, ``None`` with enough values. The unknowns are the free
    parameters, the estimated initial states and ``n_extra`` more (removed offsets); a
    record with no more values in the cost fits any of them.
    """
    n_x0 = problem.model.n_states if problem.is_estimating_x0 else 0
    unknowns = n_free + n_x0 + n_extra
    if n_free == 0 or problem.n_obs > unknowns:
        return None
    parts = [f"{n_free} free parameter{'s' * (n_free != 1)}"]
    if n_x0:
        parts.append(f"{n_x0} initial states")
    if n_extra:
        parts.append(f"{n_extra} offset{'s' * (n_extra != 1)}")
    per = max(len(problem.channels), 1)
    need = unknowns // per + 1
    rows = int(problem.mask.any(axis=1).sum())
    return (f"too little data: {problem.n_obs} measured values in the cost ({rows} "
            f"sample{'s' * (rows != 1)} of {', '.join(problem.channels)}) for {unknowns} unknowns "
            f"({' + '.join(parts)}): any parameter values fit them, so the values shown are "
            f"not estimates and have no standard error; give at least {need} samples (more "
            "for a useful estimate), or fix parameters (--fix) or the start (--x0 rest)")


def withhold_estimates(res: IdentResult, reason: str) -> IdentResult:
    """Mark ``res`` as no estimate (no success, stderr or band), ``reason`` first; returns ``res``."""
    res.success = False
    res.identifiable = False
    res.stderr = {k: math.nan for k in res.stderr}
    res.bands = None
    res.band_method = None
    res.cov_log = None
    res.singular_values = []
    if reason not in res.warnings:
        res.warnings.insert(0, reason)
    return res


@dataclass
class NMOutcome:
    """Raw outcome of :func:`minimize_log` (``final_simplex``, shape ``(n + 1, n)`` in ``u``, or ``None``)."""

    u: FloatArray
    fun: float
    nfev: int
    restarts: int
    converged: bool
    final_simplex: FloatArray | None


def minimize_log(fun: Callable[[FloatArray], float], u0: FloatArray, step: float = 0.3,
                 restarts: int = 6, maxfev: int | None = None, xatol: float = 1e-7,
                 fatol: float = 1e-14, initial_simplex: FloatArray | None = None,
                 bounds: list[tuple[float, float]] | None = None,
                 rel_improve: float = 1e-9, adaptive: bool | None = None) -> NMOutcome:
    """Minimise ``fun(u)`` with Nelder–Mead, restarting from the best vertex.

    Parameters
    ----------
    fun : callable
        Cost of the scaled coordinates ``u`` (dimensionless).
    u0 : ndarray
        Start.
    step : float
        Initial simplex edge in ``u`` (0.3 = about 35 % per parameter).
    restarts : int
        Maximum number of restarts after the first run.
    maxfev : int, optional
        Evaluation budget over all runs (default ``1000 * len(u0)``).
    initial_simplex : ndarray, optional
        Warm start (e.g. a previous window's ``final_simplex``).
    adaptive : bool, optional
        Nelder–Mead's dimension-adapted coefficients (Gao and Han; scipy's ``adaptive``);
        default: with more than four parameters.
    """
    n = u0.size
    budget = maxfev if maxfev is not None else 1000 * max(n, 1)
    if n == 0:
        f = fun(u0)
        return NMOutcome(u0, f, 1, 0, True, u0[None, :])
    nfev = 0
    best_u, best_f = np.asarray(u0, dtype=float), math.inf
    simplex = initial_simplex
    cur_step = step
    converged = False
    run = 0
    final: FloatArray | None = None
    last_status = -1
    while run <= restarts and nfev < budget:
        if simplex is None:
            simplex = np.vstack([best_u] + [best_u + cur_step * e for e in np.eye(n)])
        res = minimize(fun, simplex[0], method="Nelder-Mead", bounds=bounds,
                       options={"initial_simplex": simplex, "xatol": xatol, "fatol": fatol,
                                "maxfev": budget - nfev,
                                "adaptive": n > 4 if adaptive is None else adaptive})
        nfev += int(res.nfev)
        last_status = int(res.status)
        final = res.final_simplex[0]
        improved = best_f - res.fun
        prev = best_f
        if res.fun < best_f:
            best_u, best_f = np.asarray(res.x, dtype=float), float(res.fun)
        run += 1
        simplex = None
        cur_step = max(cur_step * 0.3, 0.01)
        if math.isfinite(prev) and improved <= rel_improve * max(abs(prev), 1e-300):
            converged = res.status == 0 or res.status == 2
            break
        if best_f == 0.0:
            converged = True
            break
    else:
        # restarts used up (not the budget): converged if the last run met its tolerances
        converged = last_status == 0 and run > restarts
    return NMOutcome(best_u, best_f, nfev, run - 1, converged, final)


def fit(problem: OutputErrorProblem, params: Parameters, restarts: int = 6,
        maxfev: int | None = None, step: float = 0.3,
        initial_simplex: FloatArray | None = None, with_stderr: bool = True,
        xatol: float = 1e-7, fatol: float = 1e-14,
        polish: bool = False, multistart: int = 0) -> tuple[IdentResult, NMOutcome]:
    """Identify the free parameters of ``problem`` by Nelder–Mead in log coordinates.

    With ``polish`` Nelder–Mead runs to ``xatol = 1e-2`` and a Levenberg–Marquardt polish on
    the residual vector finishes (Nelder–Mead carries on if it does not lower the cost).
    ``multistart > 0`` allows that many further starts (log-normal scatter 0.7, fixed seed)
    when a parameter ran more than 50x from its start or the fit did not converge; the
    lowest cost wins. ``maxfev`` bounds every run, start and polish together (default
    ``DEFAULT_MAXFEV`` per free parameter and start). ``xatol`` (relative) and ``fatol``
    (normalised cost) are scipy's tolerances per run; a ``fatol`` below the cost's rounding
    makes noisy fits run out of budget.

    Returns
    -------
    IdentResult
        The contract's result (params, stderr, cost, nfev, success, rms, identifiability).
    NMOutcome
        Raw optimiser outcome (``final_simplex`` for warm starts).
    """
    free = params.free
    theta0 = np.array([params[k].value for k in free])
    base = params.valuesdict()

    def to_params(u: FloatArray) -> dict[str, float]:
        p = dict(base)
        p.update(zip(free, theta0 * np.exp(u)))
        return p

    bounds = None
    if any(params[k].min > 0 or math.isfinite(params[k].max) for k in free):
        bounds = [(math.log(params[k].min / params[k].value) if params[k].min > 0 else -np.inf,
                   math.log(params[k].max / params[k].value) if math.isfinite(params[k].max) else np.inf)
                  for k in free]

    def cost(u: FloatArray) -> float:
        if not np.all(np.abs(u) < 30):
            return np.inf
        return problem.normalized_ss(to_params(u))

    use_polish = polish and bounds is None and len(free) > 0

    def run_from(u_start: FloatArray, simplex: FloatArray | None,
                 budget: int | None) -> tuple[NMOutcome, bool]:
        out = minimize_log(cost, u_start, step=step,
                           restarts=min(restarts, 2) if use_polish else restarts, maxfev=budget,
                           initial_simplex=simplex, bounds=bounds,
                           xatol=max(xatol, 1e-2) if use_polish else xatol,
                           fatol=max(fatol, 1e-6) if use_polish else fatol)
        converged = out.converged
        # the polish counts against the budget too (its Jacobians included): with fewer
        # evaluations left than one Jacobian it cannot take a step
        left = None if budget is None else budget - out.nfev
        if use_polish and left is not None and left <= len(free) + 1:
            converged = False  # only the loose Nelder-Mead tolerance was reached
        elif use_polish:
            u_lm, nfev_lm, ok = _lm_polish(problem, to_params, out.u, out.fun, left)
            out.nfev += nfev_lm
            if ok:
                out.u, out.fun = u_lm, cost(u_lm)
                # a polish stopped by the budget improved the fit but did not converge
                converged = left is None or nfev_lm < left
            else:  # the polish did not help: finish with Nelder-Mead at full tolerance
                left = None if budget is None else max(budget - out.nfev, 1)
                more = minimize_log(cost, out.u, step=0.05, restarts=restarts, maxfev=left,
                                    xatol=xatol, fatol=fatol)
                more.nfev += out.nfev
                more.restarts += out.restarts + 1
                out, converged = more, more.converged
        return out, converged

    own = DEFAULT_MAXFEV * max(len(free), 1)
    out, converged = run_from(np.zeros(len(free)), initial_simplex,
                              maxfev if maxfev is not None else own)
    # further starts only for a likely spurious local minimum (run-away, no convergence);
    # one that returns to the best cost (``SAME_COST``) ends the search
    tries = 0
    rng = np.random.default_rng(12345)
    while (multistart > tries and len(free) > 0
           and (np.max(np.abs(out.u)) > math.log(50.0) or not converged)
           and (maxfev is None or out.nfev < maxfev)):   # a spent budget starts nothing more
        tries += 1
        u_start = rng.normal(0.0, 0.7, len(free))
        alt, alt_conv = run_from(u_start, None, own if maxfev is None else maxfev - out.nfev)
        alt.nfev += out.nfev
        alt.restarts += out.restarts + 1
        same = abs(alt.fun - out.fun) <= SAME_COST * max(out.fun, alt.fun)
        if alt.fun < out.fun:
            out, converged = alt, alt_conv
        else:
            out.nfev, out.restarts = alt.nfev, alt.restarts
        if same:
            break
    p_hat = to_params(out.u)
    res = finish(problem, params, p_hat, out.nfev, converged, with_stderr=with_stderr)
    res.restarts = out.restarts
    return res, out


def _lm_polish(problem: OutputErrorProblem, to_params: Callable[[FloatArray], dict[str, float]],
               u0: FloatArray, f0: float, maxfev: int | None = None
               ) -> tuple[FloatArray, int, bool]:
    """Levenberg–Marquardt from ``u0`` on the normalised residuals; ``(u, nfev, improved)``.

    At most ``60 n`` iterates (``n`` free parameters) and at most ``maxfev`` residual
    evaluations in all, the finite-difference Jacobians included (:func:`lm_within`); the
    count returned includes the Jacobians.
    """
    inv = 1.0 / math.sqrt(problem.scale)
    n = problem.n_obs

    def resid(u: FloatArray) -> FloatArray:
        if not np.all(np.abs(u) < 30):
            return np.full(n, 1e6)
        try:
            r = problem.residual_vector(to_params(u)) * inv
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            return np.full(n, 1e6)
        return r if np.all(np.isfinite(r)) else np.full(n, 1e6)

    try:
        sol = lm_within(resid, u0, maxfev, max_nfev=min(60 * max(len(u0), 1),
                                                        maxfev if maxfev is not None else 1 << 62),
                        x_scale=1.0, xtol=1e-12, ftol=1e-12, gtol=1e-12)
    except (ValueError, np.linalg.LinAlgError):
        return u0, 0, False
    return sol.x, sol.nfev, bool(sol.fun <= f0 and np.isfinite(sol.fun))


def jacobian_log(problem: OutputErrorProblem, p: Mapping[str, float], free: list[str],
                 rel_step: float = 1e-5) -> FloatArray:
    """Central-difference Jacobian of the residual vector w.r.t. log-parameters.

    The ``2 n_free`` points are evaluated by
    :meth:`~estimator.identify.problem.OutputErrorProblem.residual_vectors`, a pair at a
    time (a stack of every point's residuals would be megabytes of fresh memory).

    Returns
    -------
    ndarray, shape (n_obs, n_free)
        ``-d(residual)/d(log theta)`` = ``d(prediction)/d(log theta)`` (channel units),
        C-contiguous.
    """
    if not free:
        return np.zeros((problem.n_obs, 0))
    points = []
    for k in free:
        pp, pm = dict(p), dict(p)
        pp[k] = p[k] * math.exp(rel_step)
        pm[k] = p[k] * math.exp(-rel_step)
        points += [pm, pp]
    # residual = y - yhat, so -d(residual) = d(yhat)
    J = np.empty((problem.n_obs, len(free)))
    for i in range(0, len(points), 2):
        R = problem.residual_vectors(points[i:i + 2])
        J[:, i // 2] = (R[0] - R[1]) / (2 * rel_step)
    return J


def _rms(d: FloatArray) -> float:
    """RMS of the non-NaN entries of ``d`` (NaN when there are none; no warning)."""
    v = d[~np.isnan(d)]
    return float(np.sqrt(np.mean(v * v))) if v.size else math.nan


def finish(problem: OutputErrorProblem, params: Parameters, p_hat: Mapping[str, float],
           nfev: int, converged: bool, with_stderr: bool = True) -> IdentResult:
    """Build the :class:`IdentResult` at ``p_hat``: residuals, stderr, identifiability."""
    model = problem.model
    free = params.free
    pred = problem.predict(p_hat)
    res = pred.residual
    # a response that overflows at p_hat has no finite cost (not a NaN-skipping sum's 0)
    finite = bool(np.isfinite(res[problem.mask]).all())
    ss = float(np.nansum((res * problem.w) ** 2)) if finite else math.inf
    warnings = list(problem.meas.warnings) + list(problem.warnings)
    if not finite:
        warnings.append("the model's response overflows at these parameters (no finite cost)")
    # RMS over every measured channel, not only those in the cost
    U = road_matrix(model, problem.t, problem.meas.road)
    X = simulate_states(model, p_hat, problem.t, U, pred.x0)
    allout = outputs(model, p_hat, X, U)
    rms = {c: _rms(problem.meas.measured[c] - allout[c])
           for c in model.channels + model.ride_height_channels if c in problem.meas.measured}
    stderr: dict[str, float] = {k: float("nan") for k in free}
    identifiable, sv, cov_log = finite, [], None
    short = too_little_data(problem, len(free))
    if short is not None:
        identifiable = False
        warnings.insert(0, short)
    elif with_stderr and free and finite:
        J = jacobian_log(problem, p_hat, free)
        # per-channel residual variance (sandwich estimate for the unweighted channels)
        rw = res * problem.w
        sig2 = np.nanmean(rw ** 2, axis=0)
        dof = max(problem.n_obs - len(free), 1) / max(problem.n_obs, 1)
        sig2 = sig2 / dof
        ch_of_row = np.nonzero(problem.mask)[1]
        row_sig2 = sig2[ch_of_row]
        # identifiability on the noise-normalised Jacobian (channel scale when noise-free)
        scale_c = np.sqrt(np.where(sig2 > 0, sig2, 0.0))
        ref = np.sqrt(np.nanmean((problem.Ymeas * problem.w) ** 2, axis=0))
        scale_c = np.where(scale_c > 1e-9 * np.maximum(ref, 1e-300), scale_c, np.maximum(ref, 1e-300))
        Jn = J / scale_c[ch_of_row][:, None]
        verdict = assess(Jn, free, {p.name: p.kind for p in model.params}, model.scale_invariant)
        identifiable, sv = verdict.identifiable, verdict.singular_values
        warnings += verdict.warnings
        H = J.T @ J
        try:
            Hinv = np.linalg.pinv(H, rcond=1e-12)
            Bm = (J * row_sig2[:, None]).T @ J
            cov_log = Hinv @ Bm @ Hinv
            d = np.sqrt(np.clip(np.diag(cov_log), 0, None))
            for i, k in enumerate(free):
                stderr[k] = float(p_hat[k] * d[i]) if identifiable else float("inf")
        except np.linalg.LinAlgError:
            warnings.append("could not invert the sensitivity matrix for standard errors")
        # a standard error above the value itself: the curvature does not pin it down
        loose = [k for k in free if math.isfinite(stderr[k]) and stderr[k] > UNDETERMINED * p_hat[k]]
        if loose:
            identifiable = False
            warnings += [f"not determined by this record: {k} = {p_hat[k]:.4g} has a standard "
                         f"error of {stderr[k]:.3g} (more than {UNDETERMINED:g}x its value)"
                         for k in loose]
    n_obs = problem.n_obs
    n_free = len(free)
    nss = ss / problem.scale
    aic = n_obs * math.log(max(nss, 1e-300) / n_obs) + 2 * n_free if n_obs else float("nan")
    bic = (n_obs * math.log(max(nss, 1e-300) / n_obs) + n_free * math.log(max(n_obs, 1))
           if n_obs else float("nan"))
    if not converged:
        warnings.append("Nelder–Mead stopped on its evaluation budget before converging")
    return IdentResult(
        model=model.name,
        params={k: float(v) for k, v in p_hat.items()},
        fixed=params.fixed,
        stderr=stderr,
        cost=problem.seed_cost(ss),
        nfev=nfev,
        success=bool(converged and identifiable),
        rms_residual=rms,
        identifiable=identifiable,
        warnings=warnings,
        x0=[float(v) for v in pred.x0],
        aic=aic,
        bic=bic,
        n_obs=n_obs,
        singular_values=sv,
        cov_log=cov_log,
    )
