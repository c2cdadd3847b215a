"""Output-error refit of the model augmented with one effect (Nelder–Mead in log coordinates).

Physical effects are simulated by :func:`estimator.diagnose.nlsim.simulate_effects`; the
initial state is handled by an approximate variable projection (the free response of the
linear part, exact when the effect is inactive near the start). Sensor effects keep the
exact linear fast path: the measurement is *compensated* (offset removed, lagging channels
advanced) and the ordinary :class:`~estimator.identify.OutputErrorProblem` is evaluated.
Positive parameters are optimised as ``log(theta / theta_start)``; a sensor offset as
``(offset - offset_start) / scale``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from estimator.identify import OutputErrorProblem, minimize_log
from estimator.diagnose.nlsim import simulate_effects
from suspid.io.csvio import Measurement
from suspid.models.base import FloatArray
from suspid.models.effects import Effect, PhysicalEffect, SensorEffect
from suspid.simulate import (free_coeffs_to_state, free_response_basis, modal_form, outputs,
                             simulate_states)


@dataclass
class ModelFit:
    """A fitted (base or augmented) model and its residuals.

    Attributes
    ----------
    params : dict
        Base model parameters (SI); for ``asymmetric_damping`` the base damping is the
        symmetric part.
    effect : Effect or None
    residual : dict
        ``channel -> measured - predicted`` for every measured channel (NaN where unknown).
    predicted : dict
        Every channel of the fitted model (true-sensor view: sensor effect applied).
    cost : float
        The seed cost (``sse`` or ``frobenius``) on the cost channels, SI.
    nfev : int
    x0 : ndarray
    k : int
        Number of fitted parameters (free base + effect).
    """

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


def substeps_for(problem: OutputErrorProblem, p: Mapping[str, float], effect: PhysicalEffect,
                 h: float, x0: FloatArray | None = None) -> int:
    """Internal steps per sample so the explicit effect term stays well inside stability.

    Uses the effect's stiffness at its sites (``d phi / d s'`` and ``d phi / d s`` by finite
    differences over 1.5 times the range the linear model's response covers) against the
    smallest generalised mass. A saturating law (friction) tolerates ``h * rate`` well above
    the linear stability limit; the factors were set so the discretisation error at the
    truth stays below 1e-6 of the data's sum of squares (``tests/diagnose/test_nlsim.py``).
    """
    model = problem.model
    M, *_ = model.matrices(p)
    mmin = float(np.min(np.diag(M)))
    X = simulate_states(model, p, problem.t, problem.U, x0)
    kmax, cmax = 0.0, 0.0
    for site in effect.sites(model, p):
        phi = effect.law(site, p)
        s_obs, v_obs = site.coordinate(X, problem.U)
        smax = 1.5 * float(np.max(np.abs(s_obs))) + 1e-6
        vmax = 1.5 * float(np.max(np.abs(v_obs))) + 1e-6
        for s in np.linspace(-smax, smax, 21):
            for v in np.linspace(-vmax, vmax, 41):
                ds, dv = 1e-4 * smax, 1e-4 * vmax
                kmax = max(kmax, abs(phi(s + ds, v) - phi(s - ds, v)) / (2 * ds))
                cmax = max(cmax, abs(phi(s, v + dv) - phi(s, v - dv)) / (2 * dv))
        gg = float(site.g @ site.g)
        rate_c = cmax * gg / mmin
        rate_k = math.sqrt(kmax * gg / mmin)
    need = max(h * rate_c / 4.5, h * rate_k / 0.75, 1.0)
    return int(min(math.ceil(need), 16))


class PhysicalRefit:
    """Output-error problem of the base model plus one physical effect."""

    def __init__(self, problem: OutputErrorProblem, base: Mapping[str, float], free: list[str],
                 effect: PhysicalEffect, x0: FloatArray) -> None:
        self.problem = problem
        self.model = problem.model
        self.effect0 = effect
        self.base = dict(base)
        self.sym_name: str | None = None
        if effect.name == "asymmetric_damping":
            self.sym_name = "c" if self.model.name == "quarter1" else "c1"
        self.base_free = [k for k in free if k != self.sym_name]
        self.eff_names = effect.numeric_names
        self.x0 = np.asarray(x0, dtype=float)
        self.substeps = substeps_for(problem, base, effect, problem.h or 1.0, self.x0)

    def split(self, theta: Mapping[str, float]) -> tuple[dict[str, float], PhysicalEffect]:
        p = dict(self.base)
        p.update({k: theta[k] for k in self.base_free})
        eff = self.effect0.with_values(**{k: theta[k] for k in self.eff_names})
        if self.sym_name:
            p[self.sym_name] = 0.5 * (theta["c_rebound"] + theta["c_compression"])
        return p, eff  # type: ignore[return-value]

    def simulate(self, p: Mapping[str, float], eff: PhysicalEffect,
                 x0: FloatArray) -> dict[str, FloatArray]:
        pr = self.problem
        return simulate_effects(self.model, p, [eff], pr.t, U=pr.U, x0=x0, substeps=self.substeps)

    def residual(self, theta: Mapping[str, float]) -> tuple[FloatArray, FloatArray, dict[str, FloatArray]]:
        """Weighted residual (N, p) on the cost channels, the initial state used, all channels."""
        pr = self.problem
        p, eff = self.split(theta)
        sim = self.simulate(p, eff, self.x0)
        Y = np.column_stack([sim[c] for c in pr.channels])
        x0 = self.x0
        if isinstance(pr.x0, str) and pr.x0 == "estimate":
            modal = modal_form(self.model, p)
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

    def fit(self, start: Mapping[str, float], restarts: int = 3, maxfev: int | None = None,
            step: float = 0.15, passes: int = 3) -> ModelFit:
        """Nelder–Mead from ``start`` (base and effect values by name).

        Up to ``passes`` runs: after each the initial state is re-centred on its projected
        value (the projection is linear around the current ``x0``) and Nelder–Mead
        restarts from the best point with a smaller simplex.
        """
        names = self.base_free + self.eff_names
        th0 = np.array([float(start[k]) for k in names])
        scale = self.problem.scale

        def to_theta(u: FloatArray) -> dict[str, float]:
            return dict(zip(names, th0 * np.exp(u)))

        def cost(u: FloatArray) -> float:
            if not np.all(np.abs(u) < 20):
                return np.inf
            try:
                r, _, _ = self.residual(to_theta(u))
            except (np.linalg.LinAlgError, ValueError, FloatingPointError, OverflowError):
                return np.inf
            v = float(np.sum(r * r)) / scale
            return v if np.isfinite(v) else np.inf

        budget = maxfev if maxfev is not None else 150 * len(names)
        nfev = 0
        u = np.zeros(len(names))
        f_prev = cost(u)
        for sweep in range(passes):
            # the initial state is projected linearly around self.x0; re-centre and repeat
            out = minimize_log(cost, u, step=step if sweep == 0 else step / 4,
                               restarts=restarts if sweep == 0 else 1, maxfev=budget,
                               xatol=1e-5, fatol=1e-7 * f_prev, rel_improve=1e-6)
            nfev += out.nfev
            u = out.u
            _, x0_new, _ = self.residual(to_theta(u))
            self.x0 = x0_new
            f_new = cost(u)
            if not f_new < 0.98 * out.fun:
                break
            f_prev = f_new
        theta = to_theta(u)
        r, x0, _ = self.residual(theta)
        p, eff = self.split(theta)
        self.x0 = x0
        sim = self.simulate(p, eff, x0)
        ss = float(np.sum(r * r))
        resid = {c: np.asarray(self.problem.meas.measured[c], dtype=float) - sim[c]
                 for c in self.model.channels if c in self.problem.meas.measured}
        return ModelFit(p, eff, resid, sim, self.problem.seed_cost(ss), nfev, x0, len(names))


def compensated(meas: Measurement, effect: SensorEffect, tail: int = 0) -> Measurement:
    """``meas`` with a sensor effect undone; the last ``tail`` samples of affected channels NaN."""
    chans = effect.compensate(meas.t, meas.measured)
    if tail > 0:
        for c in effect.affected():
            if c in chans:
                y = np.array(chans[c], dtype=float)
                y[-tail:] = np.nan
                chans[c] = y
    return Measurement(meas.t, dict(meas.road), chans, list(meas.warnings), meas.source)


class SensorRefit:
    """Output-error problem of the base model seen through one sensor effect."""

    def __init__(self, problem: OutputErrorProblem, base: Mapping[str, float], free: list[str],
                 effect: SensorEffect, max_delay: float = 0.1) -> None:
        self.problem = problem
        self.model = problem.model
        self.base = dict(base)
        self.free = list(free)
        self.effect0 = effect
        self.tail = 0
        if effect.name == "sensor_delay" and problem.h:
            self.tail = int(math.ceil(max_delay / problem.h)) + 1

    def sub_problem(self, eff: SensorEffect) -> OutputErrorProblem:
        pr = self.problem
        return OutputErrorProblem(self.model, compensated(pr.meas, eff, self.tail), cost=pr.cost,
                                  x0=pr.x0, weights=pr.weights)

    def fit(self, start_base: Mapping[str, float], start_effect: Mapping[str, Any],
            restarts: int = 3, maxfev: int | None = None, step: float = 0.15) -> ModelFit:
        real = [k for k in self.effect0.numeric_names if self.effect0.spec(k).kind == "real"]
        pos = [k for k in self.effect0.numeric_names if k not in real]
        names = self.free + pos + real
        th0 = np.array([float(start_base[k]) for k in self.free] + [float(start_effect[k]) for k in pos + real])
        nlog = len(self.free) + len(pos)
        rscale = np.array([max(abs(float(start_effect[k])), 1e-9) for k in real])
        scale = self.problem.scale

        def to_theta(u: FloatArray) -> dict[str, float]:
            v = np.concatenate([th0[:nlog] * np.exp(u[:nlog]), th0[nlog:] + u[nlog:] * rscale])
            return dict(zip(names, v))

        def split(theta: Mapping[str, float]) -> tuple[dict[str, float], SensorEffect]:
            p = dict(self.base)
            p.update({k: theta[k] for k in self.free})
            eff = self.effect0.with_values(**{k: theta[k] for k in pos + real})
            return p, eff  # type: ignore[return-value]

        def cost(u: FloatArray) -> float:
            if not np.all(np.abs(u[:nlog]) < 20):
                return np.inf
            p, eff = split(to_theta(u))
            try:
                r = self.sub_problem(eff).residual_vector(p)
            except (np.linalg.LinAlgError, ValueError, FloatingPointError):
                return np.inf
            v = float(r @ r) / scale
            return v if np.isfinite(v) else np.inf

        budget = maxfev if maxfev is not None else 200 * len(names)
        out = minimize_log(cost, np.zeros(len(names)), step=step, restarts=restarts, maxfev=budget,
                           xatol=1e-6, fatol=1e-14, rel_improve=1e-7)
        p, eff = split(to_theta(out.u))
        sp = self.sub_problem(eff)
        pred = sp.predict(p)
        ss = float(np.nansum((pred.residual * sp.w) ** 2))
        X = simulate_states(self.model, p, sp.t, sp.U, pred.x0)
        allout = outputs(self.model, p, X, sp.U)
        resid = {c: np.asarray(sp.meas.measured[c], dtype=float) - allout[c]
                 for c in self.model.channels if c in sp.meas.measured}
        return ModelFit(p, eff, resid, allout, sp.seed_cost(ss), out.nfev, pred.x0, len(names))


def baseline_fit(problem: OutputErrorProblem, p: Mapping[str, float], x0: FloatArray, nfev: int,
                 k: int) -> ModelFit:
    """Wrap an ordinary linear fit as a :class:`ModelFit` (residuals on every measured channel)."""
    pred = problem.predict(p)
    ss = float(np.nansum((pred.residual * problem.w) ** 2))
    X = simulate_states(problem.model, p, problem.t, problem.U, pred.x0)
    allout = outputs(problem.model, p, X, problem.U)
    resid = {c: np.asarray(problem.meas.measured[c], dtype=float) - allout[c]
             for c in problem.model.channels if c in problem.meas.measured}
    return ModelFit(dict(p), None, resid, allout, problem.seed_cost(ss), nfev, pred.x0, k)


__all__ = ["ModelFit", "PhysicalRefit", "SensorRefit", "compensated", "baseline_fit", "substeps_for"]
