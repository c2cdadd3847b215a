"""Starting values from the record itself: the data-driven start and the rescaled given start.

The equation-error regression (:mod:`estimator.identify.regression`) gives the estimate;
:func:`estimate_start` tries several filter bandwidths, compensates for the measurement
noise (:func:`_ratio_fit`) and keeps the estimate with the lowest output-error cost.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import numpy as np
from scipy.optimize import minimize

from estimator.identify.misfit import NOISE_FLOOR, noise_floor_ratio
from estimator.identify.params import Parameters
from estimator.identify.problem import OutputErrorProblem
from estimator.identify.regression import (NOISE_NEGLIGIBLE, _coef_poly, _equation_weights,
                                           _lifted_seed, _monomial_slopes, _monomials,
                                           _noise_variance, _Regression, _solve_linear,
                                           _split_linear)
from suspid.errors import UsageError
from suspid.io.csvio import Measurement
from suspid.models.base import FloatArray, SuspensionModel
from suspid.simulate import simulate_states, uniform_step

#: grid factors (relative to the start value) for parameters that enter nonlinearly
NONLIN_GRID = np.exp(np.linspace(math.log(0.05), math.log(20.0), 21))
#: normalised output-error cost below which an estimate is taken as exact (no further bandwidth)
EXACT_COST = 1e-7
#: floor of an estimate relative to the geometric mean of the others of its kind
FLOOR = 0.02
#: relative residual of the equation-error fit above which the equation weights at the
#: documented default masses are tried too, when they differ by more than ``REWEIGHT_FACTOR``
REWEIGHT_REL = 0.5
REWEIGHT_FACTOR = 30.0
#: smallest relative singular value of the regression accepted as "determined"
RANK_TOL = 1e-9
#: the noise-compensated fit (:func:`_ratio_fit`) stays within ``exp(RATIO_SPAN)`` of its start
RATIO_SPAN = 8.0
#: iterations of each of its BFGS runs (scipy's L-BFGS-B, :func:`_bfgs`)
RATIO_ITER = 200
#: its stopping tolerance on the largest gradient component (of the mean ratio, in log values)
RATIO_GTOL = 1e-6

#: common factors tried per kind of free parameter by :func:`kind_scaled_start`
KIND_GRID = 10.0 ** np.linspace(-2.0, 2.0, 5)
#: :func:`kind_scaled_start` searches at most this many kinds at once (``5**3`` costs)
KIND_MAX = 3


@dataclass
class StartEstimate:
    """A data-driven starting point: ``values`` (free parameter -> estimate, SI; empty when
    the method could not apply, ``reason`` says why), the chosen filter ``bandwidth_hz``, the
    normalised output-error ``cost`` there (1 = no fit), the adjustments made (``notes``) and
    the parameters whose estimate was replaced by a floor value (``undetermined``).
    """

    values: dict[str, float] = field(default_factory=dict)
    reason: str | None = None
    bandwidth_hz: float = float("nan")
    cost: float = float("inf")
    notes: list[str] = field(default_factory=list)
    undetermined: list[str] = field(default_factory=list)


def _bfgs(F: Callable[[FloatArray], tuple[float, FloatArray]], u0: FloatArray,
          iterations: int, gtol: float = 1e-6, span: float = math.inf
          ) -> tuple[float, FloatArray]:
    """Minimise ``F`` (value, gradient) by scipy's L-BFGS-B within ``|u| < span``.

    A component pointing out of the box stays on its edge (a run-away, judged by the
    caller). Returns ``(value, point)`` of the end point.
    """
    u = np.asarray(u0, dtype=float)
    edge = span * (1.0 - 1e-9)
    bounds = [(-edge, edge)] * u.size if math.isfinite(span) else None
    res = minimize(F, u, jac=True, method="L-BFGS-B", bounds=bounds,
                   options={"maxiter": iterations, "gtol": gtol,
                            "ftol": 8.0 * float(np.finfo(float).eps)})
    return float(res.fun), np.asarray(res.x, dtype=float)


def _ratio_fit(reg: _Regression, K: FloatArray, lin: list[str], nonlin: list[str],
               starts: Sequence[Mapping[str, float]]) -> list[dict[str, float]] | None:
    """Free parameters minimising each equation's residual over its noise share, averaged.

    With white noise in the channels, equation ``i``'s ratio ``c' G c / c' B c`` is about 1
    at the truth and larger elsewhere: unlike least squares its minimum is consistent
    (errors in variables). The mean is minimised by BFGS on the log values from each of
    ``starts``, within ``exp(RATIO_SPAN)`` of the first start (or of its own start outside
    that box). Returns every end point (free parameter -> value, SI), lowest mean ratio
    first, duplicates left out; ``None`` when no start gives a finite ratio. The caller
    chooses by the output-error cost.
    """
    if reg.B is None:
        return None
    nl = len(lin)
    free = lin + nonlin
    # the centre of the present run's box: the logarithms are taken from it
    x0 = np.ones(len(free))
    first = np.array([starts[0][k] for k in free]) if starts else x0.copy()
    big = 1e300
    # the coefficients are linear in z = theta (x) phi(eta), so each equation's two
    # quadratic forms are z' A_i z and z' D_i z: contracted with G and B once, here
    nj, nm, ni = K.shape[0], K.shape[1], K.shape[2]
    Kz = K.reshape(nj * nm, ni, K.shape[3])
    A = np.einsum("ais,st,bit->iab", Kz, reg.G, Kz)
    D = np.einsum("ais,st,bit->iab", Kz, reg.B, Kz)
    theta = np.ones(nl + 1)
    one = np.ones(1)

    def F(u: FloatArray) -> tuple[float, FloatArray]:
        if not (np.abs(u) < RATIO_SPAN).all():
            return big, np.zeros_like(u)
        x = x0 * np.exp(u)
        theta[1:] = x[:nl]
        eta = x[nl:]
        phi = _monomials(eta) if eta.size else one
        z = (theta[:, None] * phi).ravel()
        Az, Dz = A @ z, D @ z
        num, den = Az @ z, Dz @ z
        if not (den > 0).all():
            return big, np.zeros_like(u)
        q = num / den
        # dF/dz: the mean of dq_i/dz = 2 (A_i z - q_i D_i z) / den_i
        Gz = ((Az - q[:, None] * Dz) / den[:, None]).sum(axis=0).reshape(nj, nm)
        g = np.empty(u.size)
        g[:nl] = Gz[1:] @ phi
        if eta.size:
            g[nl:] = (theta @ Gz) @ _monomial_slopes(eta)
        return float(q.sum()) / ni, g * x * (2.0 / ni)

    ends: list[tuple[float, FloatArray]] = []
    for st in starts:
        v = np.array([st[k] for k in free])
        if not (np.all(v > 0) and np.all(np.isfinite(v))):
            continue
        # the box around the first start, or around this start when it lies outside that box
        centre = first if np.all(first > 0) and np.all(
            np.abs(np.log(v / first)) < RATIO_SPAN) else v
        x0[:] = centre
        u0 = np.log(v / centre)
        if not F(u0)[0] < big:
            continue
        f, u = _bfgs(F, u0, RATIO_ITER, gtol=RATIO_GTOL, span=RATIO_SPAN)
        x = centre * np.exp(u)
        if math.isfinite(f) and f < big and not any(
                np.allclose(x, y, rtol=1e-6, atol=0.0) for _, y in ends):
            ends.append((f, x))
    if not ends:
        return None
    ends.sort(key=lambda fx: fx[0])
    return [{k: float(v) for k, v in zip(free, x)} for _, x in ends]


def _floored(model: SuspensionModel, base: Mapping[str, float], lin: list[str],
             vals: dict[str, float], what: str) -> tuple[dict[str, float], list[str], list[str]]:
    """``vals`` with each of ``lin`` below ``FLOOR`` x the geometric mean of its kind raised to it.

    Such an estimate is not determined by the record; returns ``(values, floored, notes)``.
    """
    out = dict(vals)
    floored: list[str] = []
    notes: list[str] = []
    ok = [k for k in lin if vals[k] > 0 and math.isfinite(vals[k])]
    for k in lin:
        kind = model.spec(k).kind
        same = [vals[j] for j in ok if model.spec(j).kind == kind and j != k]
        floor = FLOOR * (math.exp(float(np.mean(np.log(same)))) if same else base[k])
        if not (vals[k] >= floor and math.isfinite(vals[k])):
            notes.append(f"{k}: the {what} estimate {vals[k]:.3g} is not a usable "
                         f"positive value; started at {floor:.3g}")
            out[k] = floor
            floored.append(k)
    return out, floored, notes


def estimate_start(problem: OutputErrorProblem, params: Parameters) -> StartEstimate:
    """Data-driven start of the free parameters of ``params`` for ``problem``'s record.

    Parameters
    ----------
    problem : OutputErrorProblem
        The record (one measured channel per coordinate at least), its road and the cost
        that ranks the candidate estimates.
    params : Parameters
        Fixed values and, for parameters that do not enter linearly, their grid's centre.
        Four filter bandwidths from 0.2 Hz to a fifth of Nyquist are tried in turn; the
        sweep ends at an exact estimate or, on a noisy record, one that leaves only white
        noise; otherwise the lowest output-error cost wins.

    Returns
    -------
    StartEstimate
        ``values`` holds the estimate; ``reason`` says why there is none.
    """
    model = problem.model
    meas = problem.meas
    free = params.free
    if not free:
        return StartEstimate(reason="no free parameter")
    t = problem.t
    h = uniform_step(t)
    if h is None:
        return StartEstimate(reason="the time grid is not uniform")
    base = params.valuesdict()
    lin, nonlin = _split_linear(model, base, free)
    if not lin:
        return StartEstimate(reason="no free parameter enters the equations of motion linearly")
    # the coefficients as a polynomial of the free values (when the noise compensation needs it)
    poly: list[tuple[FloatArray, FloatArray] | None] = []
    bandwidths_hz = [float(f) for f in np.geomspace(0.2, max(0.5 / h / 5.0, 0.3), 4)]
    best = StartEstimate(reason="no filter bandwidth gave a usable estimate")
    reasons: list[str] = []
    seeds: list[FloatArray] = []
    last_u: FloatArray | None = None
    best_reg: tuple[_Regression, FloatArray] | None = None
    # the noise compensation only where some channel carries measurable white noise
    noisy = any(_noise_variance(y) > NOISE_NEGLIGIBLE * float(np.nanvar(y))
                for y in (np.asarray(v, dtype=float) for v in meas.measured.values())
                if np.count_nonzero(~np.isnan(y)) > 4 and not np.any(np.isinf(y)))
    for fc in bandwidths_hz:
        if best.cost < EXACT_COST:
            break
        reg = _Regression(model, meas, t, h, problem.U, 2 * math.pi * fc)
        if reg.missing:
            return StartEstimate(reason="no measured channel of coordinate(s) "
                                        f"{', '.join(reg.missing)}: the equations of motion "
                                        "hold an unmeasured signal")
        if not np.any(reg.Q):
            return StartEstimate(reason="the record holds no motion")
        # equation weights: the known (mass) term of each equation at the start values
        wts = _equation_weights(reg, model, base)

        def solve_at(eta: FloatArray, fc: float = fc, reg: _Regression = reg,
                     wts: FloatArray = wts) -> tuple[dict[str, float], float, float]:
            p = dict(base)
            p.update({k: base[k] * float(f) for k, f in zip(nonlin, eta)})
            theta, rel, sv = _solve_linear(reg, model, p, lin, wts)
            p.update(zip(lin, (float(v) for v in theta)))
            # a negative spring or damper ranks behind every physical point of the search
            return p, rel + (1.0 if np.any(theta < 0) else 0.0), sv

        if nonlin:
            lifted = _lifted_seed(reg, model, base, lin, nonlin, wts)
            tries = seeds + ([last_u] if last_u is not None else [])
            if lifted is not None and np.all(np.abs(lifted) < 3.5):
                seeds = tries = [lifted]
            elif not seeds:  # the grid once, at the first bandwidth; later ones reuse it
                grid = list(itertools.product(NONLIN_GRID, repeat=len(nonlin))) \
                    if len(nonlin) <= 2 else [tuple([1.0] * len(nonlin))]
                scored = sorted((solve_at(np.array(g))[1], g) for g in grid)
                seeds = [np.log(np.array(g, dtype=float)) for _, g in scored[:3]]
            best_u, best_r = np.zeros(len(nonlin)), math.inf
            for g0 in tries if tries else seeds:
                res = minimize(
                    lambda u: solve_at(np.exp(u))[1] if np.all(np.abs(u) < 3.5) else np.inf, g0,
                    method="Nelder-Mead",
                    options={"initial_simplex": np.vstack([g0] + [g0 + 0.1 * e
                                                                  for e in np.eye(len(nonlin))]),
                             "xatol": 1e-5, "fatol": 1e-14, "maxfev": 60 * len(nonlin)})
                if res.fun < best_r:
                    best_u, best_r = np.asarray(res.x, dtype=float), float(res.fun)
            last_u = best_u
            p, rel, sv = solve_at(np.exp(best_u))
        else:
            p, rel, sv = solve_at(np.zeros(0))
        if rel > REWEIGHT_REL:
            # start values decades off (an absurd --init of a free mass) skew the equation
            # weights: weigh at the documented defaults as well, keep the better estimate
            alt = _equation_weights(reg, model, {**base, **{
                k: model.spec(k).default for k in free if model.spec(k).kind in ("mass", "inertia")}})
            if np.all(np.isfinite(alt)) and np.any(
                    np.abs(np.log(alt / wts)) > math.log(REWEIGHT_FACTOR)):
                eta = np.exp(last_u) if nonlin and last_u is not None else np.zeros(len(nonlin))
                p_alt, rel_alt, sv_alt = solve_at(eta, wts=alt)
                if (problem.normalized_ss({**base, **{k: float(p_alt[k]) for k in free}})
                        < problem.normalized_ss({**base, **{k: float(p[k]) for k in free}})):
                    p, rel, sv, wts = p_alt, rel_alt, sv_alt, alt
        if sv < RANK_TOL:
            reasons.append(f"{fc:.3g} Hz: too little excitation to separate "
                           f"{', '.join(lin)} (relative singular value {sv:.1e})")
            continue
        vals, floored, notes = _floored(model, base, lin, {k: float(p[k]) for k in free},
                                        "equation-error")
        cost = problem.normalized_ss({**base, **vals})
        if cost >= EXACT_COST and noisy and not poly:
            poly.append(_coef_poly(model, base, lin, nonlin))
        if cost >= EXACT_COST and noisy and poly[0] is not None:
            # not exact: the noise-compensated fit from this estimate and from the given start
            given = {k: base[k] for k in free}
            starts = [vals, given]
            if nonlin:
                starts += [{**vals, **{k: base[k] for k in nonlin}},
                           {**given, **{k: vals[k] for k in nonlin}}]
            # every run's end point is a candidate; the output-error cost chooses
            for comp in _ratio_fit(reg.with_noise(), poly[0][0], lin, nonlin, starts) or []:
                comp, comp_floored, comp_notes = _floored(model, base, lin, comp,
                                                          "noise-compensated")
                comp_cost = problem.normalized_ss({**base, **comp})
                if comp_cost < cost:
                    vals, cost, floored = comp, comp_cost, comp_floored
                    notes = ["compensated for the measurement noise (errors in variables)",
                             *comp_notes]
        if cost < best.cost:
            best = StartEstimate(values=vals, bandwidth_hz=fc, cost=float(cost), notes=notes,
                                 undetermined=floored)
            best_reg = (reg, wts)
            if noisy and not floored and noise_floor_ratio(problem, {**base, **vals}) <= NOISE_FLOOR:
                break  # leaves only white noise: no other bandwidth can do better
    if not best.values and reasons:
        best.reason = "; ".join(reasons)
    if best.values and best.cost >= EXACT_COST and best_reg is not None:
        best = _refine_iv(problem, best, best_reg[0], best_reg[1], base, lin, nonlin, h)
    return best


def _refine_iv(problem: OutputErrorProblem, est: StartEstimate, reg: "_Regression",
               wts: FloatArray, base: Mapping[str, float], lin: list[str], nonlin: list[str],
               h: float) -> StartEstimate:
    """Four instrumental-variable iterations against the noise bias in the regressors.

    The instruments are the filtered noise-free simulation at the current estimate; an
    iterate is kept only when it lowers the output-error cost.
    """
    model = problem.model
    nq = len(model.coords)
    for _ in range(4):
        p = {**base, **est.values}
        try:
            x0 = problem.predict(p).x0
            X = simulate_states(model, p, problem.t, problem.U, x0)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            break
        if not np.all(np.isfinite(X)):
            break
        sim = Measurement(t=problem.t, road=problem.meas.road,
                          measured={**{c: X[:, i] for i, c in enumerate(model.coords)},
                                    **{f"{c}_dot": X[:, nq + i] for i, c in enumerate(model.coords)}})
        iv = reg.with_instruments(_Regression(model, sim, problem.t, h, problem.U,
                                              2 * math.pi * est.bandwidth_hz,
                                              segments=reg.segments))
        q = dict(p)
        if nonlin:
            u = _lifted_seed(iv, model, p, lin, nonlin, wts)
            if u is not None and np.all(np.abs(u) < 3):
                q.update({k: p[k] * math.exp(v) for k, v in zip(nonlin, u)})
        theta, _, _ = _solve_linear(iv, model, q, lin, wts)
        if not np.all(theta > 0):
            break
        q.update(zip(lin, (float(v) for v in theta)))
        vals = {k: float(q[k]) for k in est.values}
        cost = problem.normalized_ss({**base, **vals})
        if not cost < est.cost:
            break
        est = StartEstimate(values=vals, bandwidth_hz=est.bandwidth_hz, cost=float(cost),
                            notes=est.notes + ["refined by instrumental variables"],
                            undetermined=est.undetermined)
    return est


def data_driven_start(model: SuspensionModel, data: Measurement, fixed: Mapping[str, float],
                      init: Mapping[str, float] | None = None, cost: str = "sse") -> dict[str, float]:
    """Starting values of every free parameter of ``model`` from the record ``data``.

    Parameters
    ----------
    model : SuspensionModel
    data : Measurement
        The record (measured channels, road).
    fixed : mapping
        Known parameters (SI); every other parameter is free.
    init : mapping, optional
        Centre of the search for nonlinear parameters (default: the model's defaults).
    cost : {"sse", "frobenius"}
        Cost used to rank the candidate estimates.

    Returns
    -------
    dict
        Free parameter -> estimate (SI); empty when the record does not allow one.
    """
    free_init = {k: v for k, v in (init or {}).items() if k not in fixed}
    params = Parameters.for_model(model, fix=fixed, init=free_init)
    problem = OutputErrorProblem(model, data, cost=cost)
    return dict(estimate_start(problem, params).values)


def kind_scaled_start(problem: OutputErrorProblem, params: Parameters
                      ) -> tuple[Parameters, dict[str, float], float] | None:
    """The given start with each kind of free parameter rescaled by one common factor.

    A start off by one factor per kind (every damper 10x, lengths in the wrong unit) keeps
    the ratios within each kind: a grid of factors (``KIND_GRID``, at most ``KIND_MAX``
    kinds) and a short Nelder-Mead find them.

    Parameters
    ----------
    problem : OutputErrorProblem
        The record and cost.
    params : Parameters
        Fixed values and the given start of the free parameters.

    Returns
    -------
    tuple or None
        ``(start, factors, cost)``: the rescaled start, each kind's factor and its
        normalised cost; ``None`` with more than ``KIND_MAX`` kinds or no finite cost.
    """
    free = params.free
    model = problem.model
    kinds = sorted({model.spec(k).kind for k in free})
    if not free or len(kinds) > KIND_MAX:
        return None
    base = params.valuesdict()
    col = [kinds.index(model.spec(k).kind) for k in free]

    def scaled(u: FloatArray) -> dict[str, float]:
        out = dict(base)
        for k, j in zip(free, col):
            out[k] = min(max(base[k] * math.exp(float(u[j])), params[k].min), params[k].max)
        return out

    def cost(u: FloatArray) -> float:
        return problem.normalized_ss(scaled(u)) if np.all(np.abs(u) < 6.0) else math.inf

    logs = np.log(KIND_GRID)
    c0, u0 = min(((cost(g), g) for g in map(np.array, itertools.product(logs, repeat=len(kinds)))),
                 key=lambda cu: cu[0])
    if not math.isfinite(c0):
        return None
    step = 0.5 * float(logs[1] - logs[0])
    res = minimize(cost, u0, method="Nelder-Mead",
                   options={"initial_simplex": np.vstack([u0] + [u0 + step * e
                                                                 for e in np.eye(len(kinds))]),
                            "xatol": 1e-2, "fatol": 1e-6, "maxfev": 60 * len(kinds)})
    u, c = (np.asarray(res.x, dtype=float), float(res.fun)) if res.fun <= c0 else (u0, c0)
    out = params.with_values({k: v for k, v in scaled(u).items() if k in free})
    return out, {kd: math.exp(float(u[i])) for i, kd in enumerate(kinds)}, c


def cold_start(model: SuspensionModel, meas: Measurement, params: Parameters,
               cost: str = "sse") -> Parameters:
    """``params`` with its free values replaced by the data-driven start when that fits better.

    For a fit with no earlier estimate (a monitor's first window), so a far-off nominal
    start does not decide the basin.
    """
    if not params.free:
        return params
    try:
        problem = OutputErrorProblem(model, meas, cost=cost)
    except (UsageError, ValueError, np.linalg.LinAlgError):
        return params
    est = estimate_start(problem, params)
    vals = {k: v for k, v in est.values.items() if k not in est.undetermined}
    if not vals:
        return params
    out = params.with_values(vals)
    if problem.normalized_ss(out.valuesdict()) < problem.normalized_ss(params.valuesdict()):
        return out
    return params
