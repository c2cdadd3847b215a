"""Closing the loop with the road unknown: a strut effect found in the body equations.

Each registered strut effect's regressors on the measured ride heights become one more column
of :func:`~estimator.identify.roadfree.fit_road_unknown`; the candidate explaining most of the
equation error with a physical coefficient clear of its standard error wins.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from estimator.identify.params import Parameters
from estimator.identify.result import IdentResult
from estimator.identify.roadfree import band_limit, body_equations, fit_road_unknown
from suspid.effects import PhysicalEffect, Site, effect_classes
from suspid.io.csvio import Measurement
from suspid.models.base import FloatArray, SuspensionModel

#: a candidate's coefficient must stand this many standard errors clear of zero
T_MIN = 6.0
#: and explain at least this share of the body equations' mean-square error
EXPLAINED_MIN = 0.05


@dataclass
class RoadUnknownDiagnosis:
    """Outcome of :func:`diagnose_road_unknown` (``to_json`` gives ``suspid diagnose``'s object)."""

    model: str
    baseline: IdentResult
    augmented: IdentResult
    effect: PhysicalEffect | None
    sites: list[str]
    evidence: dict[str, Any]
    warnings: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        def block(r: IdentResult) -> dict[str, Any]:
            return {"params": {k: float(v) for k, v in r.params.items()},
                    "rms_residual": dict(r.rms_residual), "cost": float(r.cost),
                    "stderr": dict(r.stderr)}

        return {"model": self.model, "road": "unknown", "baseline": block(self.baseline),
                "augmented": block(self.augmented),
                "effect": self.effect.to_json() if self.effect is not None else None,
                "evidence": self.evidence, "warnings": list(self.warnings)}


def _strut_motion(model: SuspensionModel, meas: Measurement, p: Mapping[str, float],
                  f_hi: float) -> tuple[list[FloatArray], list[FloatArray], list[float]] | None:
    """Each strut's extension (m) and rate (m/s), low-passed at ``f_hi`` (Hz), and the white-noise std
    (m/s) of the rate; None when a strut is unmeasured or gapped.
    """
    t = np.asarray(meas.t, dtype=float)
    if t.size < 64:
        return None
    n = t.size
    f = np.fft.rfftfreq(n, float(np.median(np.diff(t))))
    taper = 0.5 - 0.5 * np.cos(np.pi * np.clip((f_hi - f) / (0.2 * f_hi), 0.0, 1.0))
    s_list, sd_list, noise = [], [], []
    for name, site in zip(model.ride_heights, model.strut_sites(p)):
        if name in meas.measured:
            d = np.asarray(meas.measured[name], dtype=float)
        elif not np.any(site.gr != 0.0) and all(
                model.coords[k] in meas.measured for k in np.flatnonzero(site.g)):
            d = sum((site.g[k] * np.asarray(meas.measured[model.coords[k]], dtype=float)
                     for k in np.flatnonzero(site.g)), start=np.zeros(t.size))
        else:
            return None
        if not np.all(np.isfinite(d)):
            return None
        X = np.fft.rfft(d - d.mean())
        s_list.append(np.fft.irfft(X * taper, n) + d.mean())
        sd_list.append(np.fft.irfft(2j * np.pi * f * (X * taper), n))
        floor = float(np.median(np.abs(X[-max(4, int(0.16 * f.size)):]) ** 2) / math.log(2.0))  # per bin
        rate_var = 2.0 * floor * float(np.sum((2 * np.pi * f * taper) ** 2)) / (n * n)
        noise.append(math.sqrt(max(rate_var, 0.0)))
    return s_list, sd_list, noise


def _columns(cls: type[PhysicalEffect], trial: dict[str, Any], sites: Sequence[Site],
             idx: Sequence[int], rows: Sequence[int], s: Sequence[FloatArray],
             sd: Sequence[FloatArray], base: Mapping[str, float], noise: Sequence[float]
             ) -> dict[str, list[FloatArray]]:
    """The effect's force columns in the body rows, summed over the struts ``idx``."""
    cols: dict[str, list[FloatArray]] = {}
    for i in idx:
        regs = cls.regressors(sites[i], s[i], sd[i], base, trial, noise[i])
        for j, col in enumerate(regs):
            key = f"{cls.name}#{j}"
            per_row = cols.setdefault(key, [np.zeros(col.size) for _ in rows])
            for r, row in enumerate(rows):
                per_row[r] = per_row[r] + sites[i].g[row] * col
    return cols


def diagnose_road_unknown(model: SuspensionModel, meas: Measurement, params: Parameters
                          ) -> RoadUnknownDiagnosis:
    """Fit the body equations, try every strut effect in them, keep the one the equation error supports."""
    base = fit_road_unknown(model, meas, params, misfit_fails=False)
    warnings = list(base.warnings)
    evidence: dict[str, Any] = {"road": "unknown", "candidates": [], "not_tried": {}}
    p = dict(base.params)
    eqs = body_equations(model, meas.measured, p)
    f_hi = band_limit(model, p)
    motion = _strut_motion(model, meas, p, f_hi) if base.success and not eqs.shift else None
    if motion is None:
        why = ("the baseline fit did not succeed" if not base.success else
               "each strut's ride height (or wheel position) is needed without gaps to form an "
               "effect's force; accelerations alone give the deflection only inside the "
               "linear equations")
        evidence["verdict"] = f"no effect tried: {why}"
        return RoadUnknownDiagnosis(model.name, base, base, None, [], evidence, warnings)
    s, sd, noise = motion
    sites = model.strut_sites(p)
    rows = list(eqs.rows)
    best: tuple[float, Any] | None = None
    for name, cls in effect_classes().items():
        if not (isinstance(cls, type) and issubclass(cls, PhysicalEffect)):
            continue
        if cls.site_kind != "strut":
            evidence["not_tried"][name] = "acts at the tyre, through the unmeasured road"
            continue
        variants: list[tuple[str, list[int]]] = []
        if cls.sites_problem(sites) is None:
            variants.append(("every strut", list(range(len(sites)))))
        if len(sites) > 1:
            variants += [(sites[i].name, [i]) for i in range(len(sites))
                         if cls.sites_problem([sites[i]]) is None]
        if not variants:
            evidence["not_tried"][name] = str(cls.sites_problem(sites))
            continue
        for label, idx in variants:
            for trial in cls.screen_trials([sites[i] for i in idx], [s[i] for i in idx],
                                           [sd[i] for i in idx]):
                cols = _columns(cls, trial, sites, idx, rows, s, sd, p, noise)
                fit = fit_road_unknown(model, meas, params, extra=cols, jackknife=False,
                                       misfit_fails=False)
                coef = np.array([fit.params.pop(k) for k in cols])
                ses = np.array([fit.stderr.pop(k) for k in cols])
                tstat = float(np.max(np.abs(coef) / np.maximum(ses, 1e-300)))
                explained = 1.0 - fit.cost / base.cost if base.cost > 0 else 0.0
                try:
                    eparams, plausible, note = cls.from_coefficients(
                        coef, fit.params, trial, [sites[i] for i in idx],
                        [noise[i] for i in idx])
                except NotImplementedError:
                    continue
                row = {"name": name, "sites": label, "trial": trial,
                       "params": {k: float(v) if isinstance(v, (int, float)) else v
                                  for k, v in eparams.items()},
                       "t": round(tstat, 2), "explained": round(float(explained), 4),
                       "plausible": bool(plausible)}
                if note:
                    row["note"] = note
                evidence["candidates"].append(row)
                if plausible and tstat >= T_MIN and explained >= EXPLAINED_MIN:
                    if best is None or explained > best[0]:
                        best = (float(explained), (cls, eparams, cols, label, idx))
    for name, cls in effect_classes().items():
        if not (isinstance(cls, type) and issubclass(cls, PhysicalEffect)) and name not in evidence["not_tried"]:
            evidence["not_tried"][name] = "a sensor effect: constant offsets drop out of the body equations"
    evidence["candidates"].sort(key=lambda c: -c["explained"])
    if best is None:
        evidence["verdict"] = (f"no strut effect explains the equation error (none with t >= "
                               f"{T_MIN:g} and >= {EXPLAINED_MIN:.0%} of it, physically plausible): "
                               "no missing effect found")
        return RoadUnknownDiagnosis(model.name, base, base, None, [], evidence, warnings)
    _, (cls, eparams, cols, label, idx) = best
    effect = cls(**eparams)
    augmented = fit_road_unknown(model, meas, params, extra=cols, misfit_fails=False)
    evidence["effect_stderr"] = {k: augmented.stderr.pop(k) for k in cols}
    for k in cols:
        augmented.params.pop(k)
    try:
        overrides = effect.base_overrides([sites[i] for i in idx])
    except ValueError:
        overrides = {}
    augmented.params.update(overrides)
    evidence["verdict"] = (f"{cls.name} at {label}: explains {best[0]:.1%} of the body equations' "
                           f"mean-square error")
    evidence["effect_sites"] = [sites[i].name for i in idx]
    return RoadUnknownDiagnosis(model.name, base, augmented, effect,
                                [sites[i].name for i in idx], evidence, warnings)
