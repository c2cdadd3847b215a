"""Honest 3-sigma bands: the curvature band where the cost is quadratic, the profile
likelihood where it is not.

For each free parameter ``k`` (log coordinates, Gauss–Newton inverse ``G``, sandwich
covariance ``V``, noise scale ``s_k^2 = V_kk / G_kk``) the statistic
``r^2(t) = (S_prof(t) - S_min) / s_k^2`` equals ``t^2 / V_kk`` for a linear response;
the band is ``{theta_k : r^2 <= 9}``. First ``r^2`` is checked at both ends of the
curvature band along the Gauss–Newton profile path: within ``NONLINEARITY`` the
curvature band stands. Otherwise the other parameters are refitted at each trial ``t``
and the ends found where ``r = 3`` (secant steps); a side still below 3 at ``FAR`` does
not close, and the result is not identifiable. Noise-free records (relative standard
errors below ``NOISE_FREE``) keep the curvature band.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
import numpy as np

from estimator.identify.problem import OutputErrorProblem
from estimator.identify.result import IdentResult
from estimator.identify.solver import jacobian_log
from suspid.models.base import FloatArray

#: band half-width in standard deviations
SIGMAS = 3.0
#: relative deviation of the cost's rise at a band end from the quadratic prediction above
#: which the profile replaces the curvature band
NONLINEARITY = 0.1
#: relative standard error below which a record counts as noise-free (band kept)
NOISE_FREE = 1e-6
#: how far (factor) a profile is followed before it counts as not closing
FAR = 1000.0
#: |r - SIGMAS| at which a band end counts as found
R_TOL = 0.03
#: accuracy of a profile refit's cost in units of ``s_k^2``: moves ``r`` near 3 by at most
#: ``TOL_S / 6`` (0.002), a fifteenth of ``R_TOL``
TOL_S = 1e-2


@dataclass
class Bands:
    """The reported bands, ``name -> (lo, hi)`` (SI; ``0`` / ``inf`` for a side that does not
    close), each one's ``method`` (``"curvature"`` or ``"profile"``), ``nonlinearity``
    (``r^2 / 9`` at the curvature band's lower and upper end), the ``open_sides``
    (``"below"``, ``"above"``) whose profile does not reach 3 sigma, the residual
    evaluations spent and whether a profile found a lower cost than the optimum.
    """

    bands: dict[str, tuple[float, float]] = field(default_factory=dict)
    method: dict[str, str] = field(default_factory=dict)
    nonlinearity: dict[str, tuple[float, float]] = field(default_factory=dict)
    open_sides: dict[str, list[str]] = field(default_factory=dict)
    nfev: int = 0
    lower_cost: bool = False


class _Cost:
    """Weighted sum of squares and residuals of ``problem`` in log coordinates about ``p``."""

    def __init__(self, problem: OutputErrorProblem, p: dict[str, float], free: list[str]) -> None:
        self.problem = problem
        self.p = dict(p)
        self.free = free
        self.theta = np.array([p[k] for k in free])
        self.nfev = 0

    def resid(self, u: FloatArray) -> FloatArray | None:
        if not np.all(np.abs(u) < 30):
            return None
        q = dict(self.p)
        q.update(zip(self.free, self.theta * np.exp(u)))
        self.nfev += 1
        try:
            r = self.problem.residual_vector(q)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            return None
        return r if np.all(np.isfinite(r)) else None

    def resids(self, us: list[FloatArray]) -> list[FloatArray] | None:
        """Residuals at every ``u`` of ``us``, or ``None`` as soon as one is unavailable."""
        n = next((i for i, u in enumerate(us) if not np.all(np.abs(u) < 30)), len(us))
        qs = []
        for u in us[:n]:
            q = dict(self.p)
            q.update(zip(self.free, self.theta * np.exp(u)))
            qs.append(q)
        try:
            R = self.problem.residual_vectors(qs) if qs else np.empty((0, 0))
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            rows: list[FloatArray] = []  # one by one: the same errors, the same count
            for u in us:
                r = self.resid(u)
                if r is None:
                    return None
                rows.append(r)
            return rows
        rows = []
        for r in R:
            self.nfev += 1
            if not np.all(np.isfinite(r)):
                return None
            rows.append(r)
        return rows if n == len(us) else None

    def ss(self, u: FloatArray) -> float:
        r = self.resid(u)
        return math.inf if r is None else float(r @ r)


def _fd_jacobian(cost: _Cost, u: FloatArray, r: FloatArray, others: list[int]
                 ) -> FloatArray | None:
    """Forward-difference Jacobian of the residual in the coordinates ``others``, the shifted
    points evaluated together (:meth:`_Cost.resids`).
    """
    h = 1e-6
    ups = []
    for i in others:
        up = u.copy()
        up[i] += h
        ups.append(up)
    rows = cost.resids(ups)
    if rows is None:
        return None
    J = np.empty((r.size, len(others)))
    for j, rp in enumerate(rows):
        J[:, j] = (rp - r) / h
    return J


def _conditional_min(cost: _Cost, k: int, t: float, u0: FloatArray, s0: float,
                     tol: float, jac: dict[int, FloatArray]) -> tuple[float, FloatArray]:
    """``min S`` over every coordinate but ``k`` (held at ``t``), Levenberg–Marquardt from ``u0``.

    Stops when a step gains no more than ``max(tol, 1e-10 s0)``. ``jac`` (``k -> Jacobian``)
    carries the Jacobian between profile points, updated by Broyden's formula and
    recomputed by finite differences only when a step from it fails.
    """
    n = u0.size
    others = [i for i in range(n) if i != k]
    u = u0.copy()
    u[k] = t
    r = cost.resid(u)
    if r is None:
        return math.inf, u
    f = float(r @ r)
    if not others:
        return f, u
    lam = 1e-3
    stop = max(tol, 1e-10 * max(s0, 1e-300))
    J = jac.get(k)
    fresh = False
    if J is None or J.shape[0] != r.size:
        J = _fd_jacobian(cost, u, r, others)
        fresh = True
        if J is None:
            return f, u
    for _ in range(12):
        A = J.T @ J
        g = J.T @ r
        improved = done = small = False
        for _ in range(8):
            step = np.linalg.solve(A + lam * np.diag(np.diag(A) + 1e-12 * np.trace(A) / len(others)), -g)
            un = u.copy()
            un[others] += step
            rn = cost.resid(un)
            fn = math.inf if rn is None else float(rn @ rn)
            if rn is not None and fn < f:
                improved = True
                # converged: a small step (finite-difference Jacobian), or a decrease the
                # Gauss-Newton model predicted to within ``stop``
                done = fresh and ((f - fn) <= stop or np.max(np.abs(step)) < 1e-9)
                if not done:
                    pred = -float(2.0 * (g @ step) + step @ A @ step)
                    try:
                        full = float(g @ np.linalg.lstsq(A, g, rcond=1e-12)[0])
                    except np.linalg.LinAlgError:
                        full = math.inf
                    done = abs((f - fn) - pred) + max(full - pred, 0.0) <= stop
                small = (f - fn) <= stop
                # Broyden update of the Jacobian along the step taken
                J = J + np.outer(rn - r - J @ step, step) / float(step @ step)
                fresh = False
                u, r, f = un, rn, fn
                lam = max(lam / 4.0, 1e-9)
                break
            lam *= 8.0
            if not fresh:
                break  # a stale Jacobian: recompute it before raising the damping further
        if done:
            break
        if not improved or small:
            if fresh:
                break
            J = _fd_jacobian(cost, u, r, others)
            fresh = True
            lam = 1e-3
            if J is None:
                return f, u
    if J is not None:
        jac[k] = J
    return f, u


def _from_origin(t: float, r: float, t0: float) -> float | None:
    """Where ``r = SIGMAS`` on ``r(t) = SIGMAS |t| / t0 + c t^2`` through ``(t, r)``.

    The model keeps the curvature band's slope at the optimum (``t0`` its half-width in
    ``u``); ``None`` where it has no root beyond the origin on the side of ``t``.
    """
    s = abs(t) / t0
    if s <= 0:
        return None
    c = (r - SIGMAS * s) / (s * s)  # curvature of r in units of t0
    if abs(c) < 1e-12:
        return math.copysign(t0, t)
    disc = SIGMAS * SIGMAS + 4 * c * SIGMAS
    if disc < 0:
        return None
    root = (-SIGMAS + math.sqrt(disc)) / (2 * c)
    return math.copysign(root * t0, t) if root > 0 else None


def _profile_side(cost: _Cost, k: int, side: float, t0: float, s0: float, sk2: float,
                  G: FloatArray) -> tuple[float | None, bool]:
    """End of the band on one side: ``(t, lower_cost_found)``; ``t = None`` if not closed.

    The first trial point is the curvature band's end ``t0``; the next comes from
    :func:`_from_origin` (the optimum's slope and that point), later ones from secants.
    """
    n = G.shape[0]
    path = G[:, k] / G[k, k]
    limit = math.log(FAR)
    lower = False

    jac: dict[int, FloatArray] = {}

    def r_at(t: float, start: FloatArray) -> tuple[float, FloatArray]:
        nonlocal lower
        f, u = _conditional_min(cost, k, t, start, s0, TOL_S * sk2, jac)
        if f < s0 * (1 - 1e-9):
            lower = True
        return math.sqrt(max(f - s0, 0.0) / sk2), u

    t_prev, r_prev = 0.0, 0.0
    u_prev = np.zeros(n)
    t = side * min(abs(t0), limit)
    for _ in range(10):
        r, u = r_at(t, u_prev + path * (t - t_prev))
        if abs(r - SIGMAS) <= R_TOL:
            return t, lower
        if r > SIGMAS:
            # bracketed between t_prev (r_prev < 3) and t: secant inside the bracket
            lo_t, lo_r, lo_u = t_prev, r_prev, u_prev
            hi_t, hi_r = t, r
            for j in range(9):
                t_new = lo_t + (SIGMAS - lo_r) * (hi_t - lo_t) / max(hi_r - lo_r, 1e-12)
                if lo_t == 0.0:
                    q = _from_origin(hi_t, hi_r, t0)
                    if q is not None and 0 < q / hi_t < 1:
                        t_new = q
                if j == 8:
                    break  # eight points in the bracket: its last secant
                rn, un = r_at(t_new, lo_u + path * (t_new - lo_t))
                if abs(rn - SIGMAS) <= R_TOL:
                    return t_new, lower
                if rn < SIGMAS:
                    lo_t, lo_r, lo_u = t_new, rn, un
                else:
                    hi_t, hi_r = t_new, rn
            return t_new, lower
        if abs(t) >= limit:
            return None, lower
        # still inside: extrapolate the secant (r ~ linear in t), at least 1.5x further
        grow = (SIGMAS - r_prev) / max(r - r_prev, 1e-12) * (t - t_prev) + t_prev
        t_next = side * min(max(abs(grow), 1.5 * abs(t)), limit)
        q = _from_origin(t, r, t0) if t_prev == 0.0 else None
        if q is not None and q / t > 1:
            t_next = side * min(abs(q), limit)
        t_prev, r_prev, u_prev = t, r, u
        t = t_next
    return None, lower


def honest_bands(problem: OutputErrorProblem, res: IdentResult, free: list[str]) -> Bands:
    """3-sigma band of every free parameter of ``res`` (see the module's description) on
    the problem it solved: from ``res.cov_log`` (the sandwich covariance of the
    log-parameters, ``free`` in its order) and ``res.params``; empty without a covariance.
    """
    out = Bands()
    V = res.cov_log
    if V is None or not free or not np.all(np.isfinite(V)):
        return out
    V = np.asarray(V, dtype=float)
    p = {k: float(v) for k, v in res.params.items()}
    se = np.sqrt(np.clip(np.diag(V), 0.0, None))
    for i, k in enumerate(free):
        out.bands[k] = (p[k] * (1 - SIGMAS * se[i]), p[k] * (1 + SIGMAS * se[i]))
        out.method[k] = "curvature"
    if not np.any(se > NOISE_FREE):
        return out
    cost = _Cost(problem, p, free)
    J = jacobian_log(problem, p, free)
    cost.nfev += 2 * len(free)
    try:
        G: FloatArray = np.asarray(np.linalg.pinv(J.T @ J, rcond=1e-12), dtype=float)
    except np.linalg.LinAlgError:
        return out
    u0 = np.zeros(len(free))
    s0 = cost.ss(u0)
    if not math.isfinite(s0):
        return out
    for i, k in enumerate(free):
        if not (se[i] > NOISE_FREE and G[i, i] > 0):
            continue
        sk2 = V[i, i] / G[i, i]
        ratios = []
        for side in (-1.0, 1.0):
            end = 1 + side * SIGMAS * se[i]
            if end <= 0:
                ratios.append(math.nan)
                continue
            t = math.log(end)
            rise = cost.ss(G[:, i] / G[i, i] * t) - s0
            ratios.append(rise / sk2 / SIGMAS ** 2)
        out.nonlinearity[k] = (ratios[0], ratios[1])
        if all(math.isfinite(x) and abs(x - 1) <= NONLINEARITY for x in ratios):
            continue
        ends = []
        for side in (-1.0, 1.0):
            t_end, lower = _profile_side(cost, i, side, SIGMAS * se[i], s0, sk2, G)
            out.lower_cost |= lower
            ends.append(t_end)
        lo = 0.0 if ends[0] is None else p[k] * math.exp(ends[0])
        hi = math.inf if ends[1] is None else p[k] * math.exp(ends[1])
        out.bands[k] = (lo, hi)
        out.method[k] = "profile"
        sides = [s for s, e in zip(("below", "above"), ends) if e is None]
        if sides:
            out.open_sides[k] = sides
    out.nfev = cost.nfev
    return out


def apply_bands(problem: OutputErrorProblem, res: IdentResult, free: list[str]) -> IdentResult:
    """Attach the bands of ``res`` (``band_3sigma``, ``band_method``) and their verdict.

    A profile that does not close makes ``res`` not identifiable and no success, with a
    warning naming the open side. Returns ``res`` (changed in place).
    """
    if not all(math.isfinite(res.stderr.get(k, math.nan)) for k in free):
        return res  # no standard errors (not asked for, or not identifiable): no band
    b = honest_bands(problem, res, free)
    if not b.bands:
        return res
    res.bands = dict(b.bands)
    res.band_method = dict(b.method)
    res.nfev += b.nfev
    for k, sides in b.open_sides.items():
        res.identifiable = False
        res.success = False
        res.warnings.append(
            f"not identifiable: the profile likelihood of {k} stays within {SIGMAS:g} sigma "
            f"of the optimum {' and '.join(sides)} {res.params[k]:.4g} out to a factor "
            f"{FAR:g}; the record does not bound it")
    if b.lower_cost:
        res.warnings.append("the profile likelihood found a lower cost than the reported "
                            "optimum: the fit stopped short of the minimum")
    return res
