"""Close the loop: fit, analyse the residual, trace it to a missing effect, augment, refit.

:func:`diagnose` fits the linear baseline, tests its residual for whiteness, screens every
candidate effect on the residual force and output residual, refits the promising ones
(:func:`select_for_refit`) and accepts the one with the lowest BIC whose evidence passes
:class:`Thresholds`. The steps and thresholds are described in ``docs/closing-the-loop.md``.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass, field
from typing import Any, Callable, Mapping

import numpy as np
from scipy.stats import chi2

from estimator.diagnose.corners import SiteRestricted, model_limits, strut_limit_key
from estimator.identify.regrid import JITTER_FRACTION, grid_jitter, to_uniform_grid
from estimator.diagnose.refit import (ModelFit, PhysicalRefit, SensorRefit, baseline_fit,
                                      reweighted_linear_fit)
from estimator.diagnose.residuals import (ChannelStats, Motion, Screen, channel_stats, effective_n,
                                          motion_from, noise_variance, screen_physical,
                                          screen_sensor, xcorr_peak)
from estimator.identify import IdentResult, OutputErrorProblem, Parameters, fit, resolve_twin
from estimator.identify.record import OffsetCheck, check_offset, identify_record
from suspid.errors import InputError, UsageError
from suspid.io.csvio import Measurement
from suspid.models.base import FloatArray, SuspensionModel
from suspid.simulate import uniform_step
from suspid.effects import PhysicalEffect, SensorEffect, effect_classes, make_effect


#: signal RMS below this fraction of the largest channel's is numerically silent
SILENT_RMS = 1e-9


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

    def judge(self, dbic: float, p: float, explained: float) -> tuple[bool, str]:
        """Whether a refit with these statistics is accepted, and why (or why not)."""
        ok = dbic < self.dbic and p < self.lr_p and explained >= self.explained
        reason = "accepted" if ok else "; ".join(
            r for r, bad in ((f"dBIC {dbic:.3g} not below {self.dbic:g}", dbic >= self.dbic),
                             (f"LR p {p:.3g} not below {self.lr_p:g}", p >= self.lr_p),
                             (f"explains {explained:.0%} of the structured residual, needs "
                              f"{self.explained:.0%}", explained < self.explained)) if bad)
        return ok, reason


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
    #: every setting refitted when the screen had close alternatives (best by dBIC)
    alternatives: list[dict[str, Any]] = field(default_factory=list)
    #: the fit the evidence is measured against
    reference: str = "baseline"

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        if not self.alternatives:
            out.pop("alternatives")
        return out


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
    record: Measurement | None = None

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


def compare(base: ModelFit, aug: ModelFit, noise_var: Mapping[str, float],
            channels: list[str]) -> tuple[float, float, float, float, dict[str, float]]:
    """Evidence of ``aug`` against ``base``: ``(dBIC, LR p, structured fraction explained, f, rms)``.

    ``f``, the effective-sample fraction (AR(1)), scales the Gaussian log-likelihood so serially
    correlated residuals do not overstate the evidence.
    """
    common = {c: ~(np.isnan(base.residual[c]) | np.isnan(aug.residual[c])) for c in channels}
    # per channel (n, mean square) of each residual on the samples valid in both fits
    tb, ta = ({c: (int(ok.sum()), float(np.mean(f.residual[c][ok] ** 2)) if ok.any() else 0.0)
               for c, ok in common.items()} for f in (base, aug))
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
    used = [c for c in channels if tb[c][0] and tb[c][1] > 0]
    num = sum((tb[c][1] - ta[c][1]) / tb[c][1] for c in used)
    den = sum(max(tb[c][1] - noise_var.get(c, 0.0), 0.0) / tb[c][1] for c in used)
    explained = num / den if den > 0 else 0.0
    return dbic, p, explained, f, aug.rms()


#: fewest samples the residual analysis works on (its Savitzky–Golay window, cubic)
MIN_SAMPLES = 7


def diagnose(model: SuspensionModel, meas: Measurement, params: Parameters, cost: str = "sse",
             x0: str | FloatArray = "estimate", restarts: int = 3, maxfev: int | None = None,
             thresholds: Thresholds | None = None, polish: bool = True,
             multistart: int = 4) -> DiagnoseResult:
    """Fit ``model``, trace its residual to a missing effect, add it and refit.

    ``params`` are the starting and fixed values; ``cost``, ``x0``, ``restarts``, ``polish`` and
    ``multistart`` the baseline fit's settings (as for ``suspid identify``); ``maxfev`` the budget
    of every fit, Jacobians included. InputError for fewer than ``MIN_SAMPLES`` samples or a time
    grid not uniform even up to timing jitter.
    """
    th = thresholds or Thresholds()
    t = np.asarray(meas.t, dtype=float)
    if t.size < MIN_SAMPLES:
        raise InputError(f"{meas.source}: diagnose needs at least {MIN_SAMPLES} samples, "
                         f"got {t.size}")
    jitter_note = None
    if uniform_step(t) is None:
        meas, jitter_note = to_uniform_grid(meas)
        if jitter_note is None:
            d = np.diff(t)
            h, jit = grid_jitter(t)
            raise InputError(f"{meas.source}: diagnose needs uniformly spaced samples; the time "
                             f"steps range from {float(d.min()):.6g} to {float(d.max()):.6g} s, "
                             f"a sample lies {jit:.3g} s from the uniform grid of the same span "
                             f"and count, more than the {JITTER_FRACTION:g} step ({JITTER_FRACTION * h:.3g} s) "
                             "of timing jitter resampled (a gap? resample the record, or use identify)")
    problem = OutputErrorProblem(model, meas, cost=cost, x0=x0)
    def run(start: Parameters) -> IdentResult:
        return fit(problem, start, restarts=restarts, maxfev=maxfev, polish=polish,
                   multistart=multistart)[0]

    # the body alone of a quarter car has two exact answers: the twin is fitted too
    given = run(params)
    ident, twin_run, twin_note = resolve_twin(problem, params, given, run)
    if twin_run is not None:
        ident.nfev = given.nfev + twin_run[1].nfev
    if twin_note is not None:
        ident.warnings.append(twin_note)
    free = params.free
    p0 = dict(ident.params)
    base = baseline_fit(problem, p0, np.asarray(ident.x0), ident.nfev, len(free))
    channels = list(base.residual)
    h = problem.h or float(np.median(np.diff(meas.t)))
    skip = min(int(round(th.settle_s / h)), meas.t.size // 10)
    stats = {c: channel_stats(c, base.residual[c], np.asarray(meas.measured[c], dtype=float), skip=skip)
             for c in channels}
    noise_var = {c: noise_variance(base.residual[c]) for c in channels}
    warnings = ([jitter_note] if jitter_note else []) + list(ident.warnings)
    evidence: dict[str, Any] = {"thresholds": asdict(th),
                                "channels": {c: s.to_json() for c, s in stats.items()}}
    limits = model_limits(model)
    if limits:
        evidence["limits"] = limits
    mo = motion_from(model, meas, base.predicted, problem.U)
    maxlag = max(1, int(round(0.1 / h)))
    refs = {k: v for j, rn in enumerate(model.roads)
            for k, v in ((rn, mo.r[:, j]), (f"{rn}_dot", mo.rd[:, j]))}
    try:
        struts = model.strut_sites(p0)
    except UsageError:
        struts = []
    for site in struts:
        s, sd = site.coordinate(np.column_stack([mo.q, mo.qd]), np.column_stack([mo.r, mo.rd]))
        tag = site.name.replace(" ", "_")
        refs[f"{tag}_deflection"] = s
        refs[f"{tag}_rate"] = sd
    evidence["cross_correlation"] = {
        c: {k: dict(zip(("rho", "lag_s"), (lambda rl: (rl[0], rl[1] * h))(xcorr_peak(base.residual[c], v, maxlag))))
            for k, v in refs.items() if np.any(v)} for c in channels}
    top = max((s.signal_rms for s in stats.values()), default=0.0)
    silent = [c for c, s in stats.items() if s.signal_rms <= SILENT_RMS * top]
    if silent:
        evidence["silent_channels"] = silent
    evidenced = [c for c in channels if c not in silent]
    structured = [c for c, s in stats.items()
                  if c not in silent and s.white_p < th.whiteness_p
                  and s.rms > th.min_relative_rms * max(s.signal_rms, 1e-300)]
    if structured and len(problem.channels) < len(channels):
        # structure the linear model removes once fitted on every channel is not a missing effect
        p_lin, r_lin = reweighted_linear_fit(problem, p0, free, noise_var, maxfev)
        lin_stats = {c: channel_stats(c, r_lin[c], np.asarray(meas.measured[c], dtype=float), skip=skip)
                     for c in channels}
        evidence["linear_refit_all_channels"] = {
            "params": p_lin, "ljung_box_p": {c: s.ljung_box_p for c, s in lin_stats.items()},
            "mean_p": {c: s.mean_p for c, s in lin_stats.items()}}
        structured = [c for c in structured if lin_stats[c].white_p < th.whiteness_p]
    evidence["structured_channels"] = structured
    result = DiagnoseResult(model.name, base, base, None, evidence, ident, stats, motion=mo,
                            warnings=warnings, record=meas)
    if not structured:
        how = (", once the linear model is refitted on every channel"
               if "linear_refit_all_channels" in evidence else "")
        evidence["verdict"] = ("residual is white noise (Ljung-Box and zero-mean p >= "
                               f"{th.whiteness_p:g} on every channel{how}) or at numerical "
                               "precision: no missing effect")
        return result
    worst = min(structured, key=lambda c: (stats[c].white_p, -stats[c].ljung_box_q))
    if stats[worst].mean_p < stats[worst].ljung_box_p:
        lb = f"mean {stats[worst].mean:.3g} is not zero, p = {stats[worst].mean_p:.2g}, on {worst}"
    else:
        lb = f"Ljung-Box p = {stats[worst].ljung_box_p:.2g} on {worst}"
    # a constant road or position offset, checked as identify checks it: found, it is the effect
    check = check_offset(problem, params)
    offset_verdict: Verdict | None = None
    if check.offset is not None:
        offset_screen, offset_verdict, offset_fit, offset_notes = _offset_refit(
            problem, params, check, base, noise_var, evidenced, th,
            dict(restarts=restarts, maxfev=maxfev, polish=polish, multistart=multistart))
        evidence["offset"] = check.offset.to_json(removed=True)
    screens, force_summary = screen_physical(model, p0, free, mo, noise_var, h)
    evidence["force_residual"] = force_summary
    screens += screen_sensor(model, meas, p0, free, base.predicted, problem.U, th.max_delay_s)
    if offset_verdict is not None:
        screens = [s for s in screens if s.name != offset_verdict.name]
    blocked = _not_identifiable(model, screens, limits, th)
    if blocked:
        evidence["not_identifiable"] = blocked
    first, fallback = select_for_refit(screens, blocked, th)
    verdicts: list[Verdict] = []
    fits: dict[str, ModelFit] = {}
    if offset_verdict is not None:   # refitted already: identify's fit of the corrected record
        screens.append(offset_screen)
        verdicts.append(offset_verdict)
        fits[offset_verdict.name] = offset_fit
    result.screens = screens
    references: dict[tuple[str, ...], ModelFit] = {}

    def refit_candidate(sc: Screen) -> None:
        best_try: tuple[float, float, float, float, dict[str, float], ModelFit, ModelFit] | None = None
        tried: list[dict[str, Any]] = []
        for option in [sc] + list(sc.alternatives):
            try:
                fm, ref = _refit(problem, p0, free, base, option, th, mo, noise_var, references,
                                 maxfev)
            except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:
                warnings.append(f"refit with {option.name} {option.params} failed: {exc}")
                continue
            cmp = compare(ref, fm, noise_var, evidenced)
            if sc.alternatives:
                tried.append({"params": fm.effect.to_json()["params"] if fm.effect else {},
                              "dbic": cmp[0], "explained": cmp[2]})
            if best_try is None or cmp[0] < best_try[0]:
                best_try = (*cmp, fm, ref)
        if best_try is None:
            return
        dbic, p, expl, f, rms, fm, ref = best_try
        ok, reason = th.judge(dbic, p, expl)
        verdicts.append(Verdict(sc.name, dbic, p, expl, f, rms, fm.effect.to_json()["params"] if fm.effect else {},
                                ok, reason, tried,
                                "baseline" if ref is base else (ref.notes[0] if ref.notes else "reference fit")))
        fits[sc.name] = fm

    for sc in first:
        refit_candidate(sc)
    if fallback and not any(v.accepted for v in verdicts):
        for sc in fallback:
            refit_candidate(sc)
    result.verdicts = verdicts
    result.fits = fits
    evidence["candidates"] = {s.name: {"screen": s.to_json()} for s in screens}
    for v in verdicts:
        evidence["candidates"][v.name]["refit"] = v.to_json()
    accepted = sorted([v for v in verdicts if v.accepted], key=lambda v: v.dbic)
    if accepted:
        best = accepted[0]
        result.effect = fits[best.name].effect
        result.augmented = fits[best.name]
        where = ""
        if isinstance(result.effect, PhysicalEffect):
            sites = [s.name for s in result.effect.sites(model, result.augmented.params)]
            evidence["effect_sites"] = sites
            if isinstance(result.effect, SiteRestricted):
                where = f" in the {' and '.join(sites)} only"
                warnings.append(
                    f"{best.name} acts in the {' and '.join(sites)} only (evidence.effect_sites); "
                    f"the effect library's {model.name} form applies it to every strut, so "
                    "'effect' alone does not reproduce it")
            scr = next((s for s in screens if s.name == best.name), None)
            if scr is not None and scr.per_site and scr.per_site["explained"] > scr.explained + 0.05:
                vals = "; ".join(f"{k}: {_fmt(v)}" for k, v in scr.per_site["sites"].items())
                warnings.append(f"the struts disagree on {best.name} in the screening regression "
                                f"({vals}); the fitted form is{where or ' shared by every strut'}")
        evidence["verdict"] = (f"residual structured ({lb}); {best.name}{where} explains "
                               f"{best.explained:.0%} of the structured residual, dBIC "
                               f"{best.dbic:.4g}, LR p {best.lr_p:.2g}")
        if best is offset_verdict and check.offset is not None:
            evidence["verdict"] = (f"residual structured ({lb}); a constant offset, "
                                   f"{check.offset.describe(model)} at the rest position "
                                   f"(sensor_offset), explains {best.explained:.0%} of the "
                                   f"structured residual, dBIC {best.dbic:.4g}, LR p "
                                   f"{best.lr_p:.2g}")
            warnings[:] = [w if w == jitter_note else f"baseline (the record as it is): {w}"
                           for w in warnings] + offset_notes
        for name, why in blocked.items():
            warnings.append(f"{name}: {why}")
        for key, why in limits.items():
            if key.split(" ")[0] == best.name:
                warnings.append(f"{key}: {why}")
    else:
        tried = sorted(verdicts, key=lambda v: -v.explained)
        if blocked:
            why = "; ".join(blocked.values())
        elif tried:
            why = (f"best {tried[0].name} explains {tried[0].explained:.0%} of the structured "
                   f"residual ({tried[0].reason})")
        else:
            why = "no candidate's regressor correlates with the residual"
        evidence["verdict"] = f"residual structured ({lb}) but no candidate effect explains it: {why}"
        if limits and not blocked:
            evidence["verdict"] += ("; not identifiable with " + model.name + ": "
                                    + "; ".join(limits))
        evidence["unexplained"] = True
    aug_stats = {c: channel_stats(c, result.augmented.residual[c],
                                  np.asarray(meas.measured[c], dtype=float), skip=skip) for c in channels}
    evidence["augmented_channels"] = {c: s.to_json() for c, s in aug_stats.items()}
    if offset_verdict is not None and result.augmented is offset_fit:
        left = [c for c in evidenced if aug_stats[c].white_p < th.whiteness_p
                and aug_stats[c].rms > th.min_relative_rms * max(aug_stats[c].signal_rms, 1e-300)]
        if left:
            warnings.append(f"the residual is still structured with the offset removed (on "
                            f"{', '.join(left)}): diagnose the record with the offset "
                            "subtracted (evidence.offset.values) for a further effect")
    return result


def _offset_refit(problem: OutputErrorProblem, params: Parameters, check: OffsetCheck,
                  base: ModelFit, noise_var: Mapping[str, float], channels: list[str],
                  th: Thresholds, settings: Mapping[str, Any]
                  ) -> tuple[Screen, Verdict, ModelFit, list[str]]:
    """The offset :func:`~estimator.identify.record.check_offset` found, as a candidate: its screen,
    verdict, identify's fit of the record with the offsets removed and that fit's other warnings.
    """
    offset = check.offset
    if offset is None:
        raise ValueError("no offset found to refit")
    ident, fitted = identify_record(problem, params, offset="remove", check=check, **settings)
    effects = offset.effects()
    effect = max(effects, key=lambda e: abs(float(e.values["offset"])))
    fm = baseline_fit(fitted, ident.params, np.asarray(ident.x0, dtype=float), ident.nfev,
                      len(params.free) + len(effects))
    predicted = fm.predicted
    if offset.kind == "channel":
        for e in effects:
            predicted = e.apply(problem.meas.t, predicted)
    fm = dataclasses.replace(fm, effect=effect, predicted=dict(predicted),
                             notes=[f"identify's fit with the offset removed ({offset.describe(problem.model)})"])
    dbic, p, expl, f, rms = compare(base, fm, noise_var, channels)
    ok, reason = th.judge(dbic, p, expl)
    screen = Screen(effect.name, "output", 1.0 - offset.share, math.nan, True,
                    effect.to_json()["params"], dict(check.estimate.values if check.estimate else {}),
                    note=f"offset check at the data-driven start: {offset.describe(problem.model)}")
    verdict = Verdict(effect.name, dbic, p, expl, f, rms, effect.to_json()["params"], ok, reason)
    notes = [f"with the offset removed: {w}" for w in ident.warnings if not w.startswith("offset:")]
    if len(effects) > 1:
        notes.append(f"offsets on {len(effects)} columns ({offset.describe(problem.model)}); "
                     "'effect' holds the largest, evidence.offset all of them")
    return screen, verdict, fm, notes


def _fmt(v: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={x:.4g}" if isinstance(x, float) else f"{k}={x}" for k, x in v.items())


def _not_identifiable(model: SuspensionModel, screens: list[Screen], limits: Mapping[str, str],
                      th: Thresholds) -> dict[str, str]:
    """Strut effects the residual force points to in every strut with different parameters, a form no
    candidate can express: ``effect name -> sentence``.
    """
    out: dict[str, str] = {}
    for s in screens:
        ps = s.per_site
        if s.domain != "force" or not ps or not ps.get("plausible"):
            continue
        pe = float(ps["explained"])
        if pe < 0.3 or pe < 1.5 * (s.explained if s.plausible else 0.0) or pe < th.min_screen:
            continue
        vals = "; ".join(f"{k}: {_fmt(v)}" for k, v in ps["sites"].items())
        key = next((k for k in limits if k.startswith(s.name)), strut_limit_key(model))
        why = limits.get(key, "the effect library has no form with separate parameters per strut")
        out[s.name] = (f"the residual force points to {s.name} in every strut with different "
                       f"parameters (one coefficient per strut explains {pe:.0%} of it, the best "
                       f"expressible form {s.explained:.0%}; {vals}), which cannot be identified "
                       f"with {model.name}: {why}")
    return out


def select_for_refit(screens: list[Screen], blocked: Mapping[str, str],
                     th: Thresholds) -> tuple[list[Screen], list[Screen]]:
    """The screened candidates worth an output-error refit: ``(first, fallback)``.

    Physical and sensor candidates are ranked separately (their shares are not comparable);
    ``fallback``, refitted only when none of ``first`` is accepted, holds the best physical
    candidates below ``min_screen`` (the force screen is noise-bound).
    """
    reg = effect_classes()
    phys = sorted([s for s in screens if s.name in reg and reg[s.name].kind == "physical"
                   and s.plausible and s.name not in blocked], key=lambda s: -s.explained)
    sens = [s for s in screens if s.name in reg and reg[s.name].kind == "sensor"
            and s.plausible and s.explained >= th.min_screen]
    if not phys:
        return sens, []
    top = phys[:1] + [s for s in phys[1:] if s.explained >= 0.5 * phys[0].explained]
    top = top[: th.max_physical]
    if phys[0].explained >= th.min_screen:
        return [s for s in top if s.explained >= th.min_screen] + sens, []
    return sens, ([] if blocked else top)


def _x0_start(problem: OutputErrorProblem, base: ModelFit, motion: Motion) -> FloatArray:
    """Initial state for a nonlinear refit: the measured first sample where measured, else the baseline's."""
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


def _beats(base: ModelFit, problem: OutputErrorProblem,
           noise_var: Mapping[str, float] | None) -> Callable[[Mapping[str, FloatArray]], bool]:
    """``worth(simulated channels)``: True when the noise-weighted residual is below the baseline's."""
    meas = problem.meas.measured
    nv = dict(noise_var or {})
    scale = {c: 1.0 / max(float(nv.get(c, 0.0)),
                          1e-12 * float(np.nanmean(np.asarray(meas[c], dtype=float) ** 2)), 1e-300)
             for c in base.residual}
    ref = sum(scale[c] * float(np.nansum(e ** 2)) for c, e in base.residual.items())

    def worth(sim: Mapping[str, FloatArray]) -> bool:
        tot = sum(scale[c] * float(np.nansum((np.asarray(meas[c], dtype=float) - sim[c]) ** 2))
                  for c in base.residual if c in sim)
        return bool(tot < ref)

    return worth


def _refit(problem: OutputErrorProblem, p0: Mapping[str, float], free: list[str], base: ModelFit,
           sc: Screen, th: Thresholds, motion: Motion, noise_var: Mapping[str, float],
           references: dict[tuple[str, ...], ModelFit], maxfev: int | None) -> tuple[ModelFit, ModelFit]:
    """Refit the model augmented with ``sc``: the fit and the one it is judged against (the baseline,
    or the linear model fitted on the channels a sensor effect adds).
    """
    if effect_classes()[sc.name].kind == "physical":
        values = dict(sc.params)
        eff = make_effect(sc.name, **values)
        if not isinstance(eff, PhysicalEffect):
            raise ValueError(f"{sc.name} is not a physical effect")
        if sc.sites is not None:
            eff = SiteRestricted(eff, sc.sites)
        start_base = {k: (sc.base.get(k, p0[k]) if sc.base.get(k, 0) > 0 else p0[k]) for k in p0}
        rf = PhysicalRefit(problem, start_base, free, eff, _x0_start(problem, base, motion))
        start = dict(start_base)
        start.update({k: float(values[k]) for k in eff.numeric_names})
        return rf.fit(start, maxfev=maxfev, worth=_beats(base, problem, noise_var)), base
    eff = make_effect(sc.name, **sc.params)
    if not isinstance(eff, SensorEffect):
        raise ValueError(f"{sc.name} is not a sensor effect")
    rf2 = SensorRefit(problem, p0, free, eff, th.max_delay_s, noise_var)
    start_base = {k: (sc.base[k] if sc.base.get(k, 0) > 0 else p0[k]) for k in p0}
    fm = rf2.fit(start_base, sc.params, maxfev=maxfev)
    if not rf2.extra:   # the refit sees no channel the baseline's cost does not
        return fm, base
    key = (sc.name, *sorted(rf2.extra), "|", *sorted(eff.affected()))
    if key not in references:
        references[key] = rf2.fit_null(p0, maxfev)
    return fm, references[key]
