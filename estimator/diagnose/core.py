"""Close the loop: fit, analyse the residual, trace it to a missing effect, augment, refit.

:func:`diagnose` runs

1. the ordinary linear fit (:func:`estimator.identify.fit`) — the *baseline*;
2. residual analysis (:mod:`estimator.diagnose.residuals`): per-channel RMS, Ljung–Box
   whiteness, noise level, cross-correlation with the road and the suspension states, the
   residual force regressed on every physical candidate, the output residual on the sensor
   candidates;
3. if the residual is structured (Ljung–Box rejects whiteness on some channel at
   ``whiteness_p`` and the residual is above numerical precision), an output-error refit
   (Nelder–Mead) of the most promising candidates — up to ``max_physical`` physical
   effects by screening score and every sensor effect whose screen explains at least
   ``min_screen`` of the residual;
4. selection by evidence: a candidate is accepted when its refit lowers the Bayesian
   information criterion by more than ``dbic`` (computed with the per-channel Gaussian
   likelihood and an effective sample count that discounts serial correlation), its
   likelihood-ratio p-value is below ``lr_p``, and it removes at least ``explained`` of
   the *structured* part of the residual (residual minus the white-noise floor). The
   accepted candidate with the lowest BIC wins; with none accepted the result says whether
   the residual was white (nothing to explain) or structured but unexplained.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Mapping

import numpy as np
from scipy.stats import chi2

from estimator.diagnose.refit import ModelFit, PhysicalRefit, SensorRefit, baseline_fit
from estimator.diagnose.residuals import (ChannelStats, Motion, Screen, channel_stats, effective_n,
                                          motion_from, noise_variance, screen_delay,
                                          screen_physical, screen_sensor, xcorr_peak)
from estimator.identify import IdentResult, OutputErrorProblem, Parameters, fit
from suspid.io.csvio import Measurement
from suspid.models.base import FloatArray, SuspensionModel
from suspid.models.effects import REGISTRY, PhysicalEffect, SensorEffect, make_effect, strut_sites


@dataclass
class Thresholds:
    """Decision thresholds of :func:`diagnose` (see the module docstring)."""

    whiteness_p: float = 1e-3
    min_relative_rms: float = 1e-7
    dbic: float = -10.0
    lr_p: float = 1e-3
    explained: float = 0.5
    min_screen: float = 0.02
    max_physical: int = 2
    max_delay_s: float = 0.1
    #: start of the record (s) left out of the whiteness test (initial-state transient)
    settle_s: float = 0.05


@dataclass
class Verdict:
    """Evidence of one refitted candidate against the baseline."""

    name: str
    dbic: float
    lr_p: float
    explained: float
    effective_fraction: float
    rms: dict[str, float]
    params: dict[str, Any]
    accepted: bool
    reason: str

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class DiagnoseResult:
    """Outcome of :func:`diagnose` (see :meth:`to_json` for the contract's object)."""

    model: str
    baseline: ModelFit
    augmented: ModelFit
    effect: Any
    evidence: dict[str, Any]
    ident: IdentResult
    stats: dict[str, ChannelStats] = field(default_factory=dict)
    screens: list[Screen] = field(default_factory=list)
    verdicts: list[Verdict] = field(default_factory=list)
    motion: Motion | None = None
    fits: dict[str, ModelFit] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        """``baseline``, ``augmented``, ``effect``, ``evidence`` (plus ``model``, ``warnings``)."""

        def block(f: ModelFit) -> dict[str, Any]:
            return {"params": {k: float(v) for k, v in f.params.items()},
                    "rms_residual": f.rms(), "cost": float(f.cost),
                    "x0": [float(v) for v in f.x0], "nfev": int(f.nfev)}

        return {"model": self.model, "baseline": block(self.baseline),
                "augmented": block(self.augmented),
                "effect": self.effect.to_json() if self.effect is not None else None,
                "evidence": self.evidence, "warnings": list(self.warnings)}


def _loglik_terms(fitm: ModelFit, common: Mapping[str, FloatArray]) -> dict[str, tuple[int, float]]:
    """Per channel ``(n, mean square)`` of the residual on the samples valid in every fit."""
    out = {}
    for c, ok in common.items():
        e = fitm.residual[c][ok]
        out[c] = (int(e.size), float(np.mean(e ** 2)) if e.size else 0.0)
    return out


def compare(base: ModelFit, aug: ModelFit, noise_var: Mapping[str, float],
            channels: list[str]) -> tuple[float, float, float, float, dict[str, float]]:
    """Evidence of ``aug`` against ``base``: ``dBIC, LR p-value, structured fraction explained,
    effective-sample fraction`` and the augmented RMS per channel.

    The log-likelihood is Gaussian with one variance per channel (scale free across
    channels); both use the samples valid in both fits. The effective-sample fraction
    (AR(1) of the augmented residual) scales the likelihood ratio so serially correlated
    residuals do not overstate the evidence.
    """
    common = {c: ~(np.isnan(base.residual[c]) | np.isnan(aug.residual[c])) for c in channels}
    tb, ta = _loglik_terms(base, common), _loglik_terms(aug, common)
    tiny = 1e-300
    dll = sum(0.5 * n * (math.log(max(tb[c][1], tiny)) - math.log(max(ta[c][1], tiny)))
              for c, (n, _) in tb.items() if n)
    ntot = sum(n for n, _ in tb.values())
    fr = [effective_n(aug.residual[c][common[c]]) / max(int(common[c].sum()), 1) for c in channels]
    f = float(np.clip(np.mean(fr), 1.0 / max(ntot, 1), 1.0)) if fr else 1.0
    dk = aug.k - base.k
    dbic = -2.0 * f * dll + dk * math.log(max(ntot * f, 2.0))
    lr = 2.0 * f * dll
    p = float(chi2.sf(lr, max(dk, 1))) if lr > 0 else 1.0
    num, den = 0.0, 0.0
    for c in channels:
        n, msb = tb[c]
        _, msa = ta[c]
        if n == 0 or msb <= 0:
            continue
        num += (msb - msa) / msb
        den += max(msb - noise_var.get(c, 0.0), 0.0) / msb
    explained = num / den if den > 0 else 0.0
    return dbic, p, explained, f, aug.rms()


def diagnose(model: SuspensionModel, meas: Measurement, params: Parameters, cost: str = "sse",
             x0: str | FloatArray = "estimate", restarts: int = 3, maxfev: int | None = None,
             thresholds: Thresholds | None = None) -> DiagnoseResult:
    """Fit ``model``, trace its residual to a missing effect, add it and refit.

    Parameters
    ----------
    model : SuspensionModel
        The declared linear model.
    meas : Measurement
        The record (CSV or decoded CAN log).
    params : Parameters
        Starting values, fixed parameters (e.g. weighed masses) as for ``identify``.
    cost : {"sse", "frobenius"}
        The seed cost of every fit.
    x0 : "estimate", "rest" or ndarray
        Initial-state handling (as for ``identify``).
    restarts, maxfev
        Nelder–Mead settings of the baseline fit.
    thresholds : Thresholds, optional
        Decision thresholds.

    Returns
    -------
    DiagnoseResult
    """
    th = thresholds or Thresholds()
    problem = OutputErrorProblem(model, meas, cost=cost, x0=x0)
    ident, _ = fit(problem, params, restarts=restarts, maxfev=maxfev)
    free = params.free
    p0 = dict(ident.params)
    base = baseline_fit(problem, p0, np.asarray(ident.x0), ident.nfev, len(free))
    channels = list(base.residual)
    h0 = problem.h or float(np.median(np.diff(meas.t)))
    skip = min(int(round(th.settle_s / h0)), meas.t.size // 10)
    stats = {c: channel_stats(c, base.residual[c], np.asarray(meas.measured[c], dtype=float), skip=skip)
             for c in channels}
    noise_var = {c: noise_variance(base.residual[c]) for c in channels}
    warnings = list(ident.warnings)
    evidence: dict[str, Any] = {"thresholds": asdict(th),
                                "channels": {c: s.to_json() for c, s in stats.items()}}
    # cross-correlation with inputs and states
    mo = motion_from(model, meas, base.predicted, problem.U)
    h = problem.h or float(np.median(np.diff(meas.t)))
    maxlag = max(1, int(round(0.1 / h)))
    refs: dict[str, FloatArray] = {}
    for j, rn in enumerate(model.roads):
        refs[rn] = mo.r[:, j]
        refs[f"{rn}_dot"] = mo.rd[:, j]
    for site in strut_sites(model, p0):
        s, sd = site.coordinate(np.column_stack([mo.q, mo.qd]), np.column_stack([mo.r, mo.rd]))
        tag = site.name.replace(" ", "_")
        refs[f"{tag}_deflection"] = s
        refs[f"{tag}_rate"] = sd
    evidence["cross_correlation"] = {
        c: {k: dict(zip(("rho", "lag_s"), (lambda rl: (rl[0], rl[1] * h))(xcorr_peak(base.residual[c], v, maxlag))))
            for k, v in refs.items() if np.any(v)} for c in channels}
    structured = [c for c, s in stats.items()
                  if s.ljung_box_p < th.whiteness_p and s.rms > th.min_relative_rms * max(s.signal_rms, 1e-300)]
    evidence["structured_channels"] = structured
    result = DiagnoseResult(model.name, base, base, None, evidence, ident, stats, motion=mo,
                            warnings=warnings)
    if not structured:
        evidence["verdict"] = ("residual is white noise (Ljung-Box p >= "
                               f"{th.whiteness_p:g} on every channel) or at numerical precision: "
                               "no missing effect")
        return result
    # screening
    screens, force_summary = screen_physical(model, p0, free, mo)
    evidence["force_residual"] = force_summary
    dscreen = screen_delay(model, meas, p0, free, base.predicted, problem.U, th.max_delay_s)
    if dscreen is not None:
        screens.append(dscreen)
    screens += screen_sensor(model, meas.t, base.residual, base.predicted, th.max_delay_s)
    result.screens = screens
    force = sorted([s for s in screens if s.domain == "force" and s.plausible and s.explained >= th.min_screen],
                   key=lambda s: -s.explained)
    if force:
        force = [s for s in force if s.explained >= 0.5 * force[0].explained][: th.max_physical]
    sens = [s for s in screens if s.domain == "output" and s.plausible and s.explained >= th.min_screen]
    verdicts: list[Verdict] = []
    fits: dict[str, ModelFit] = {}
    for sc in force + sens:
        try:
            fm = _refit(problem, p0, free, base, sc, th, mo)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:
            warnings.append(f"refit with {sc.name} failed: {exc}")
            continue
        dbic, p, expl, f, rms = compare(base, fm, noise_var, channels)
        ok = dbic < th.dbic and p < th.lr_p and expl >= th.explained
        reason = "accepted" if ok else "; ".join(
            r for r, bad in ((f"dBIC {dbic:.3g} not below {th.dbic:g}", dbic >= th.dbic),
                             (f"LR p {p:.3g} not below {th.lr_p:g}", p >= th.lr_p),
                             (f"explains {expl:.0%} of the structured residual, needs "
                              f"{th.explained:.0%}", expl < th.explained)) if bad)
        verdicts.append(Verdict(sc.name, dbic, p, expl, f, rms, fm.effect.to_json()["params"] if fm.effect else {},
                                ok, reason))
        fits[sc.name] = fm
    result.verdicts = verdicts
    result.fits = fits
    evidence["candidates"] = {s.name: {"screen": s.to_json()} for s in screens}
    for v in verdicts:
        evidence["candidates"][v.name]["refit"] = v.to_json()
    accepted = sorted([v for v in verdicts if v.accepted], key=lambda v: v.dbic)
    worst = max(structured, key=lambda c: stats[c].ljung_box_q)
    lb = f"Ljung-Box p = {stats[worst].ljung_box_p:.2g} on {worst}"
    if accepted:
        best = accepted[0]
        result.effect = fits[best.name].effect
        result.augmented = fits[best.name]
        evidence["verdict"] = (f"residual structured ({lb}); {best.name} explains "
                               f"{best.explained:.0%} of the structured residual, dBIC "
                               f"{best.dbic:.4g}, LR p {best.lr_p:.2g}")
    else:
        tried = sorted(verdicts, key=lambda v: -v.explained)
        if tried:
            bv = tried[0]
            evidence["verdict"] = (f"residual structured ({lb}) but no candidate effect explains it: "
                                   f"best {bv.name} explains {bv.explained:.0%} of the structured "
                                   f"residual ({bv.reason})")
        else:
            evidence["verdict"] = (f"residual structured ({lb}) but no candidate effect explains it: "
                                   "no candidate's regressor correlates with the residual")
        evidence["unexplained"] = True
    aug_stats = {c: channel_stats(c, result.augmented.residual[c],
                                  np.asarray(meas.measured[c], dtype=float), skip=skip) for c in channels}
    evidence["augmented_channels"] = {c: s.to_json() for c, s in aug_stats.items()}
    return result


def _x0_start(problem: OutputErrorProblem, base: ModelFit, motion: Motion) -> FloatArray:
    """Initial state for a nonlinear refit: the measured first sample where a coordinate's
    position and velocity are measured (the linear fit's ``x0`` is biased by the missing
    effect), else the baseline's estimate. With ``x0="rest"`` or a given state, that one."""
    if not (isinstance(problem.x0, str) and problem.x0 == "estimate"):
        return np.asarray(base.x0, dtype=float)
    model = problem.model
    nq = len(model.coords)
    x0 = np.array(base.x0, dtype=float)
    for i, c in enumerate(model.coords):
        if motion.source.get(c) == "measured" and motion.source.get(f"{c}_dot") in ("measured", "derived"):
            x0[i] = motion.q[0, i]
            x0[nq + i] = motion.qd[0, i]
    return x0


def _refit(problem: OutputErrorProblem, p0: Mapping[str, float], free: list[str], base: ModelFit,
           sc: Screen, th: Thresholds, motion: Motion) -> ModelFit:
    """Refit the model augmented with the screened candidate ``sc``."""
    if sc.name in REGISTRY and REGISTRY[sc.name].kind == "physical":
        values = dict(sc.params)
        eff = make_effect(sc.name, **values)
        if not isinstance(eff, PhysicalEffect):
            raise ValueError(f"{sc.name} is not a physical effect")
        start_base = {k: (sc.base.get(k, p0[k]) if sc.base.get(k, 0) > 0 else p0[k]) for k in p0}
        rf = PhysicalRefit(problem, start_base, free, eff, _x0_start(problem, base, motion))
        start = dict(start_base)
        start.update({k: float(values[k]) for k in eff.numeric_names})
        return rf.fit(start)
    eff = make_effect(sc.name, **sc.params)
    if not isinstance(eff, SensorEffect):
        raise ValueError(f"{sc.name} is not a sensor effect")
    rf2 = SensorRefit(problem, p0, free, eff, th.max_delay_s)
    start_base = {k: (sc.base[k] if sc.base.get(k, 0) > 0 else p0[k]) for k in p0}
    return rf2.fit(start_base, sc.params)


__all__ = ["diagnose", "DiagnoseResult", "Thresholds", "Verdict", "compare"]
