"""Output-error refit of the model augmented with one effect (:func:`nm_then_lm`, log coordinates).

Physical effects are simulated by :func:`suspid.nlsim.simulate_effects` with enough internal
steps (:func:`substeps_for`); the initial state by an approximate variable projection. Sensor
effects keep the linear fast path on the *compensated* measurement (:class:`SensorRefit`).
:func:`reweighted_linear_fit` refits the declared linear model on every channel.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

from estimator.identify import OutputErrorProblem, minimize_log
from estimator.identify.lm import lm_within
from estimator.diagnose.residuals import shift_allpass
from suspid.errors import UsageError
from suspid.io.csvio import Measurement
from suspid.models.base import AffinePieces, FloatArray
from suspid.effects import Effect, PhysicalEffect, SensorEffect
from suspid.nlsim import simulate_effects
from suspid.simulate import (free_coeffs_to_state, free_response_basis, mass_inverse, modal_form,
                             outputs, simulate_states)


@dataclass
class ModelFit:
    """A fitted (base or augmented) model: parameters (SI), effect, residuals, the seed ``cost``."""

    params: dict[str, float]
    effect: Effect | None
    residual: dict[str, FloatArray]
    predicted: dict[str, FloatArray]
    cost: float
    nfev: int
    x0: FloatArray
    k: int
    notes: list[str] = field(default_factory=list)

    def rms(self) -> dict[str, float]:
        """RMS residual per measured channel (SI)."""
        return {c: float(np.sqrt(np.nanmean(e ** 2))) for c, e in self.residual.items()}


def all_channels(problem: OutputErrorProblem, p: Mapping[str, float],
                 x0: FloatArray) -> dict[str, FloatArray]:
    """Every channel of the linear model at ``p`` from ``x0`` on the problem's record."""
    aff = problem.pieces(p)
    X = simulate_states(problem.model, p, problem.t, problem.U, x0, affine=aff)
    return outputs(problem.model, p, X, problem.U, aff)


def residuals_of(model_channels: tuple[str, ...] | list[str], measured: Mapping[str, FloatArray],
                 predicted: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
    """``channel -> measured - predicted`` for each of ``model_channels`` that is measured."""
    return {c: np.asarray(measured[c], dtype=float) - predicted[c]
            for c in model_channels if c in measured}


def substeps_for(problem: OutputErrorProblem, p: Mapping[str, float], effect: PhysicalEffect,
                 h: float, x0: FloatArray | None = None, affine: AffinePieces | None = None) -> int:
    """Internal steps per sample (1 to :data:`MAX_SUBSTEPS`) so the explicit effect term stays stable.

    The effect's stiffness against each site's inverse mass ``g . M^-1 . g`` bounds the step; the
    count is then doubled while that still changes the channels by more than :data:`ACCURACY`.
    """
    model = problem.model
    Minv = mass_inverse(model, p, affine)
    X = simulate_states(model, p, problem.t, problem.U, x0, affine=affine)
    rate_c, rate_k = 0.0, 0.0
    for site in effect.sites(model, p):
        phi = effect.law(site, p)
        s_obs, v_obs = site.coordinate(X, problem.U)
        smax = 1.5 * float(np.max(np.abs(s_obs))) + 1e-6
        vmax = 1.5 * float(np.max(np.abs(v_obs))) + 1e-6
        kmax, cmax = 0.0, 0.0
        ds, dv = 1e-4 * smax, 1e-4 * vmax
        for s in np.linspace(-smax, smax, 21):
            for v in np.linspace(-vmax, vmax, 41):
                kmax = max(kmax, abs(phi(s + ds, v) - phi(s - ds, v)) / (2 * ds))
                cmax = max(cmax, abs(phi(s, v + dv) - phi(s, v - dv)) / (2 * dv))
        inv_mass = float(site.g @ Minv @ site.g)
        rate_c = max(rate_c, cmax * inv_mass)
        rate_k = max(rate_k, math.sqrt(kmax * inv_mass))
    need = max(h * rate_c / _RATE_C_LIMIT, h * rate_k / _RATE_K_LIMIT, 1.0)
    sub = int(min(math.ceil(need), MAX_SUBSTEPS))
    if problem.h is None:
        return sub
    chans = [c for c in problem.model.channels if c in problem.meas.measured]
    data_ss = sum(float(np.nansum(np.asarray(problem.meas.measured[c], dtype=float) ** 2)) for c in chans)
    if data_ss <= 0:
        return sub
    prev = simulate_effects(model, p, [effect], problem.t, U=problem.U, x0=x0, substeps=sub,
                            affine=affine)
    while sub < MAX_SUBSTEPS:
        nxt = simulate_effects(model, p, [effect], problem.t, U=problem.U, x0=x0,
                               substeps=min(2 * sub, MAX_SUBSTEPS), affine=affine)
        change = sum(float(np.sum((nxt[c] - prev[c]) ** 2)) for c in chans)
        if change <= ACCURACY * data_ss:
            break
        sub, prev = min(2 * sub, MAX_SUBSTEPS), nxt
    return sub


#: most internal steps per sample of the refit's simulator
MAX_SUBSTEPS = 16
#: largest change of the simulated channels' sum of squares (fraction of the data's) when
#: the substeps are doubled
ACCURACY = 1e-6
#: largest ``h * c_eff / m_eff`` (damping-like effect stiffness) per substep
_RATE_C_LIMIT = 4.5 / 1.82
#: largest ``h * sqrt(k_eff / m_eff)`` (spring-like effect stiffness) per substep
_RATE_K_LIMIT = 0.75 / math.sqrt(1.82)


def forward_pieces(problem: OutputErrorProblem, base: Mapping[str, float],
                   free: list[str] | None = None) -> AffinePieces:
    """The forward model's affine pieces for a refit moving ``free``: the problem's own when they apply."""
    own = problem.affine
    if own is not None and own.matches(base) and set(free or own.names) <= set(own.names):
        return own
    return problem.model.affine(base, free)


class PhysicalRefit:
    """Output-error problem of the base model plus one physical effect (affine pieces built once)."""

    def __init__(self, problem: OutputErrorProblem, base: Mapping[str, float], free: list[str],
                 effect: PhysicalEffect, x0: FloatArray) -> None:
        self.problem = problem
        self.model = problem.model
        self.effect0 = effect
        self.base = dict(base)
        self.sites = effect.sites(self.model, base)
        self.tied = list(effect.base_overrides(self.sites))
        self.base_free = [k for k in free if k not in self.tied]
        self.eff_names = effect.numeric_names
        self.x0 = np.asarray(x0, dtype=float)
        moving = list(dict.fromkeys(self.base_free + self.tied))
        self.affine = forward_pieces(problem, self.base, moving)
        self.substeps = substeps_for(problem, base, effect, problem.h or 1.0, self.x0, self.affine)

    def split(self, theta: Mapping[str, float]) -> tuple[dict[str, float], PhysicalEffect]:
        p = dict(self.base)
        p.update({k: theta[k] for k in self.base_free})
        eff = self.effect0.with_values(**{k: theta[k] for k in self.eff_names})
        if self.tied and isinstance(eff, PhysicalEffect):
            p.update(eff.base_overrides(self.sites))
        return p, eff

    def simulate(self, p: Mapping[str, float], eff: PhysicalEffect,
                 x0: FloatArray) -> dict[str, FloatArray]:
        pr = self.problem
        return simulate_effects(self.model, p, [eff], pr.t, U=pr.U, x0=x0, substeps=self.substeps,
                                affine=self.affine)

    def residual(self, theta: Mapping[str, float]) -> tuple[FloatArray, FloatArray, dict[str, FloatArray]]:
        """Weighted residual (N, p) on the cost channels, the initial state used, all channels."""
        pr = self.problem
        p, eff = self.split(theta)
        sim = self.simulate(p, eff, self.x0)
        Y = np.column_stack([sim[c] for c in pr.channels])
        x0 = self.x0
        if isinstance(pr.x0, str) and pr.x0 == "estimate":
            modal = modal_form(self.model, p, self.affine)
            if modal is not None and pr.h is not None:
                Cm, _ = pr._output_maps(modal.A, modal.B)
                G = free_response_basis(modal, pr.h, pr.t.size, Cm)
                R = ((pr.Ymeas0 - Y) * pr.w * pr.mask).reshape(-1)
                Gm = (G * (pr.w[None, :, None] * pr.mask[:, :, None])).reshape(-1, G.shape[2])
                sol, *_ = np.linalg.lstsq(Gm, R, rcond=1e-10)
                dx0 = free_coeffs_to_state(modal, sol)
                if np.all(np.isfinite(dx0)):
                    x0 = self.x0 + dx0
                    Y = Y + G.reshape(-1, G.shape[2]).dot(sol).reshape(Y.shape)
        res = np.where(pr.mask, pr.Ymeas - Y, 0.0) * pr.w
        return res, x0, sim

    def fit(self, start: Mapping[str, float], maxfev: int | None = None,
            worth: Callable[[Mapping[str, FloatArray]], bool] | None = None) -> ModelFit:
        """Nelder–Mead to about 1 %, then Levenberg–Marquardt, from ``start`` (SI, by name).

        Up to 3 runs, restarted while re-centring the initial state or re-checking the
        substeps changes the problem; ``worth(channels)``: whether finer simulation is worth it.
        """
        names = self.base_free + self.eff_names
        th0 = np.array([float(start[k]) for k in names])
        pr = self.problem
        inv = 1.0 / math.sqrt(pr.scale)
        big = np.full(int(pr.mask.sum()), 1e3)
        logc = np.array([True] * len(self.base_free)
                        + [self.effect0.spec(k).kind != "real" for k in self.eff_names])
        rscale = np.where(logc, 1.0, np.maximum(np.abs(th0), 1e-9))

        def to_theta(u: FloatArray) -> dict[str, float]:
            return dict(zip(names, np.where(logc, th0 * np.exp(np.where(logc, u, 0.0)), th0 + u * rscale)))

        def vec(u: FloatArray) -> FloatArray:
            if not np.all(np.abs(u[logc]) < 20):
                return big
            try:
                r, _, _ = self.residual(to_theta(u))
            except (np.linalg.LinAlgError, ValueError, FloatingPointError, OverflowError):
                return big
            v = r[pr.mask] * inv
            return v if np.all(np.isfinite(v)) else big

        nfev = 0
        u = np.zeros(len(names))
        coarse = True
        for sweep in range(3):
            left = None if maxfev is None else maxfev - nfev
            if left is not None and left <= 0:
                break
            u, f, n_used = nm_then_lm(vec, u, step=0.15 if sweep == 0 else 0.15 / 4,
                                      restarts=3 if sweep == 0 else 1,
                                      maxfev=150 * len(names) if left is None else left,
                                      coarse=coarse, cap=left)
            nfev += n_used
            theta = to_theta(u)
            self.x0 = self.residual(theta)[1]
            finer = False
            if worth is None or worth(self.simulate(*self.split(theta), self.x0)):
                try:    # re-check the internal steps at theta: finer if more are needed
                    sub = substeps_for(pr, *self.split(theta), pr.h or 1.0, self.x0, self.affine)
                except (np.linalg.LinAlgError, ValueError, FloatingPointError, OverflowError):
                    sub = 0
                finer = sub > self.substeps
                self.substeps = max(sub, self.substeps)
            v = vec(u)
            recentred = float(v @ v) < 0.98 * f
            if not (finer or recentred):
                break
            coarse = recentred
        theta = to_theta(u)
        r, x0, _ = self.residual(theta)
        p, eff = self.split(theta)
        self.x0 = x0
        sim = self.simulate(p, eff, x0)
        ss = float(np.sum(r * r))
        resid = residuals_of(self.model.channels, pr.meas.measured, sim)
        return ModelFit(p, eff, resid, sim, pr.seed_cost(ss), nfev, x0, len(names))


def nm_then_lm(vec: Callable[[FloatArray], FloatArray], u0: FloatArray, step: float = 0.15,
               restarts: int = 3, maxfev: int | None = None,
               coarse: bool = True, cap: int | None = None) -> tuple[FloatArray, float, int]:
    """Minimise ``|vec(u)|^2``: a short Nelder–Mead into the basin, then a Levenberg–Marquardt polish.

    If the polish does not lower the cost, Nelder–Mead carries on at full tolerance; ``cap`` bounds
    all evaluations. Returns ``(u, |vec(u)|^2, nfev)``.
    """
    n = u0.size
    total = cap if cap is not None else 1 << 62
    budget = min(maxfev if maxfev is not None else 150 * max(n, 1), total)

    def cost(u: FloatArray) -> float:
        v = vec(u)
        return float(v @ v)

    if n == 0:
        return u0, cost(u0), 1
    f0 = cost(u0)
    if coarse and total > 2:
        out = minimize_log(cost, u0, step=step, restarts=min(restarts, 1),
                           maxfev=min(budget, 10 * (n + 1), total - 1), xatol=1e-2,
                           fatol=1e-4 * f0, rel_improve=1e-4)
        u1, f1, nfev = out.u, out.fun, out.nfev + 1
    else:
        u1, f1, nfev = np.asarray(u0, dtype=float), f0, 1
    if total - nfev > n + 1:
        try:
            sol = lm_within(vec, u1, None if cap is None else total - nfev,
                            max_nfev=min(12 * (n + 1), total - nfev), diff_step=1e-6,
                            xtol=1e-10, ftol=1e-10, gtol=1e-10)
            nfev += sol.nfev
            if np.isfinite(sol.fun) and sol.fun <= f1:
                return sol.x, sol.fun, nfev
        except (ValueError, np.linalg.LinAlgError):
            pass
    left = min(budget, total - nfev)
    if left <= 0:
        return u1, f1, nfev
    more = minimize_log(cost, u1, step=0.05, restarts=restarts, maxfev=left,
                        xatol=1e-5, fatol=1e-7 * f1, rel_improve=1e-6)
    if more.fun <= f1:
        return more.u, more.fun, nfev + more.nfev
    return u1, f1, nfev + more.nfev


def compensated(meas: Measurement, effect: SensorEffect | None, tail: int = 0,
                affected: list[str] | None = None) -> Measurement:
    """``meas`` with a sensor effect undone (delays all-pass); the last ``tail`` affected samples NaN.

    ``effect=None`` leaves the data but drops the same tail of ``affected`` (the reference).
    """
    if effect is None:
        chans = dict(meas.measured)
    elif effect.time_shift:
        chans = dict(meas.measured)
        for c in effect.affected():
            if c in chans:
                chans[c] = shift_allpass(meas.t, np.asarray(chans[c], dtype=float),
                                         float(effect.values[effect.time_shift]))
    else:
        chans = effect.compensate(meas.t, meas.measured)
    if tail > 0:
        for c in (effect.affected() if effect is not None else list(affected or [])):
            if c in chans:
                y = np.array(chans[c], dtype=float)
                y[-tail:] = np.nan
                chans[c] = y
    return Measurement(meas.t, dict(meas.road), chans, list(meas.warnings), meas.source)


class SensorRefit:
    """Output-error problem of the base model seen through one sensor effect.

    Affected channels outside the cost join the residual, weighted by their noise so each counts as
    one more cost channel; the tail of ``max_delay`` (s) is left out.
    """

    def __init__(self, problem: OutputErrorProblem, base: Mapping[str, float], free: list[str],
                 effect: SensorEffect, max_delay: float = 0.1,
                 noise_var: Mapping[str, float] | None = None) -> None:
        self.problem = problem
        self.model = problem.model
        self.base = dict(base)
        self.free = list(free)
        self.effect0 = effect
        self.tail = 0
        if effect.time_shift and problem.h:
            self.tail = int(math.ceil(max_delay / problem.h)) + 1
        self.extra = [c for c in effect.affected()
                      if c in problem.meas.measured and c not in problem.channels]
        self.weights: dict[str, float] | None = None
        self.channels = list(problem.channels)
        if self.extra:
            nv = dict(noise_var or {})
            meas = problem.meas.measured

            def sigma(c: str) -> float:
                v = math.sqrt(max(float(nv.get(c, 0.0)), 0.0))
                ref = float(np.sqrt(np.nanmean(np.asarray(meas[c], dtype=float) ** 2)))
                return max(v, 1e-6 * ref, 1e-300)

            w_user = {c: float((problem.weights or {}).get(c, 1.0)) for c in problem.channels}
            ref = float(np.mean([sigma(c) * w_user[c] for c in problem.channels]))
            self.weights = dict(w_user)
            self.weights.update({c: ref / sigma(c) for c in self.extra})
            self.channels += self.extra
        self.affine = forward_pieces(problem, self.base)

    def sub_problem(self, eff: SensorEffect | None) -> OutputErrorProblem:
        """The linear problem with ``eff`` undone (plus affected channels); ``None``: no effect."""
        pr = self.problem
        meas = compensated(pr.meas, eff, self.tail, self.effect0.affected())
        if not self.extra:
            return OutputErrorProblem(self.model, meas, cost=pr.cost, x0=pr.x0, weights=pr.weights,
                                      affine=self.affine)
        sub = Measurement(meas.t, meas.road, {c: meas.measured[c] for c in self.channels},
                          list(meas.warnings), meas.source)
        return OutputErrorProblem(self.model, sub, cost="frobenius", x0=pr.x0, weights=self.weights,
                                  affine=self.affine)

    def fit(self, start_base: Mapping[str, float], start_effect: Mapping[str, Any],
            maxfev: int | None = None) -> ModelFit:
        """Fit base and effect parameters from the screening start (see :func:`nm_then_lm`).

        ``maxfev`` bounds the whole refit (default 200 per fitted parameter).
        """
        real = [k for k in self.effect0.numeric_names if self.effect0.spec(k).kind == "real"]
        pos = [k for k in self.effect0.numeric_names if k not in real]
        names = self.free + pos + real
        th0 = np.array([float(start_base[k]) for k in self.free] + [float(start_effect[k]) for k in pos + real])
        nlog = len(self.free) + len(pos)
        rscale = np.array([max(abs(float(start_effect[k])), 1e-9) for k in real])
        sp0 = self.sub_problem(self.effect0.with_values(**{k: start_effect[k] for k in pos + real}))
        inv = 1.0 / math.sqrt(sp0.scale)
        big = np.full(sp0.n_obs, 1e3)

        def to_theta(u: FloatArray) -> dict[str, float]:
            v = np.concatenate([th0[:nlog] * np.exp(u[:nlog]), th0[nlog:] + u[nlog:] * rscale])
            return dict(zip(names, v))

        def split(theta: Mapping[str, float]) -> tuple[dict[str, float], SensorEffect]:
            p = dict(self.base)
            p.update({k: theta[k] for k in self.free})
            eff = self.effect0.with_values(**{k: theta[k] for k in pos + real})
            return p, eff

        def vec(u: FloatArray) -> FloatArray:
            if not np.all(np.abs(u[:nlog]) < 20):
                return big
            p, eff = split(to_theta(u))
            try:
                r = self.sub_problem(eff).residual_vector(p) * inv
            except (np.linalg.LinAlgError, ValueError, FloatingPointError, UsageError):
                return big
            return r if r.size == big.size and np.all(np.isfinite(r)) else big

        budget = maxfev if maxfev is not None else 200 * len(names)
        u, _, nfev = nm_then_lm(vec, np.zeros(len(names)), maxfev=budget, cap=maxfev)
        p, eff = split(to_theta(u))
        return self._model_fit(p, eff, nfev, len(names))

    def fit_null(self, start_base: Mapping[str, float], maxfev: int | None = None) -> ModelFit:
        """The declared linear model fitted as :meth:`fit` fits the augmented one, without the effect
        (the fair reference when the effect adds channels).
        """
        sp = self.sub_problem(None)
        inv = 1.0 / math.sqrt(sp.scale)
        q, nfev = _lm_log(lambda q: sp.residual_vector(q) * inv, self.base, self.free, maxfev, sp.n_obs,
                          1e3, (UsageError,))
        out = self._model_fit(q, None, nfev, len(self.free))
        out.notes.append("declared linear model fitted on " + ", ".join(self.channels)
                         + " (noise-weighted), without the effect")
        return out

    def _model_fit(self, p: dict[str, float], eff: SensorEffect | None, nfev: int, k: int) -> ModelFit:
        """Residuals of every measured channel (compensated data) and the seed cost."""
        sp = self.sub_problem(eff)
        pred = sp.predict(p)
        allout = all_channels(sp, p, pred.x0)
        comp = compensated(self.problem.meas, eff, self.tail, self.effect0.affected()).measured
        resid = residuals_of(self.model.channels, comp, allout)
        pr = self.problem
        ss = float(sum(np.nansum((float((pr.weights or {}).get(c, 1.0)) * resid[c]) ** 2)
                       for c in pr.channels))
        return ModelFit(p, eff, resid, allout, pr.seed_cost(ss), nfev, pred.x0, k)


def _lm_log(residual: Callable[[dict[str, float]], FloatArray], base: Mapping[str, float], free: list[str],
            maxfev: int | None, n_obs: int, big: float,
            errors: tuple[type[Exception], ...] = ()) -> tuple[dict[str, float], int]:
    """Levenberg–Marquardt of ``residual`` over ``free`` in log coordinates from ``base``: (params, nfev)."""
    th0 = np.array([float(base[k]) for k in free])
    bad = np.full(n_obs, big)
    caught: tuple[type[Exception], ...] = (np.linalg.LinAlgError, ValueError, FloatingPointError, *errors)

    def params_of(u: FloatArray) -> dict[str, float]:
        q = dict(base)
        q.update(zip(free, th0 * np.exp(u)))
        return q

    def vec(u: FloatArray) -> FloatArray:
        if not np.all(np.abs(u) < 20):
            return bad
        try:
            r = residual(params_of(u))
        except caught:
            return bad
        return r if r.size == n_obs and np.all(np.isfinite(r)) else bad

    u0 = np.zeros(len(free))
    u, nfev = u0, 1
    if free:
        try:
            sol = lm_within(vec, u0, maxfev, max_nfev=30 * (len(free) + 1),
                            diff_step=1e-6, xtol=1e-10, ftol=1e-10, gtol=1e-10)
            nfev = sol.nfev
            r0 = vec(u0)
            if sol.fun <= float(r0 @ r0):
                u = sol.x
        except (ValueError, np.linalg.LinAlgError):
            pass
    return params_of(u), nfev


def reweighted_linear_fit(problem: OutputErrorProblem, p: Mapping[str, float], free: list[str],
                          noise_var: Mapping[str, float],
                          maxfev: int | None = None) -> tuple[dict[str, float], dict[str, FloatArray]]:
    """The declared linear model refitted on every measured channel, each weighted by its noise:
    what this fit cannot whiten the linear model cannot explain. Returns parameters and residuals.
    """
    model = problem.model
    meas = problem.meas
    chans = [c for c in model.channels if c in meas.measured]
    w = {}
    for c in chans:
        y = np.asarray(meas.measured[c], dtype=float)
        ref = float(np.sqrt(np.nanmean(y ** 2))) if np.any(~np.isnan(y)) else 1.0
        w[c] = 1.0 / max(math.sqrt(max(float(noise_var.get(c, 0.0)), 0.0)), 1e-9 * ref, 1e-300)
    sub = Measurement(meas.t, meas.road, {c: meas.measured[c] for c in chans}, list(meas.warnings),
                      meas.source)
    pr = OutputErrorProblem(model, sub, cost="frobenius", x0=problem.x0, weights=w,
                            affine=forward_pieces(problem, p))
    q, _ = _lm_log(pr.residual_vector, p, free, maxfev, pr.n_obs, 1e6)
    pred = pr.predict(q)
    return q, residuals_of(chans, meas.measured, all_channels(pr, q, pred.x0))


def baseline_fit(problem: OutputErrorProblem, p: Mapping[str, float], x0: FloatArray, nfev: int,
                 k: int) -> ModelFit:
    """Wrap an ordinary linear fit as a :class:`ModelFit` (residuals on every measured channel)."""
    pred = problem.predict(p)
    ss = float(np.nansum((pred.residual * problem.w) ** 2))
    allout = all_channels(problem, p, pred.x0)
    resid = residuals_of(problem.model.channels, problem.meas.measured, allout)
    return ModelFit(dict(p), None, resid, allout, problem.seed_cost(ss), nfev, pred.x0, k)
