"""Run the seed's designs: simulate each target curve, identify, score.

Free parameters start at ``init_scale`` times the truth; masses and inertia are fixed at the
truth unless ``free_masses``. Noise-free success: every identified parameter within 1 % of the
truth; noisy success: every free parameter within its run's closed 3-sigma band (:func:`band_of`).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np
from scipy.stats import binom, chi2

from estimator.doe.design import DESIGNS, FS, HORIZON, Experiment, experiments, time_grid
from estimator.identify import OutputErrorProblem, Parameters, fit
from estimator.identify.result import IdentResult
from estimator.identify.multistart import fit_from_starts
from suspid.errors import UsageError
from suspid.io.csvio import Measurement
from suspid.models import SuspensionModel, get_model
from suspid.simulate import simulate

#: noise-free success tolerance (relative), the contract's 1 %
TOL = 0.01
#: noisy success band (standard errors)
SIGMAS = 3.0
#: probability a Gaussian value lies beyond ``SIGMAS`` standard errors (0.27 %)
JOINT_ALPHA = math.erfc(SIGMAS / math.sqrt(2.0))


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


@dataclass
class Settings:
    """How one design is run: free parameters start at ``init_scale`` x truth (masses and inertia at
    ``mass_init_scale`` when given); ``noise`` a fraction of each channel's std, seeded by ``seed +
    experiment id``; Nelder-Mead settings of :func:`estimator.identify.fit`; ``stages``: horizon
    continuation (the first fractions of the record first, later stages from ``polish_step``,
    ``early_*`` before the last); the record's ``horizon`` (s) and ``fs`` (Hz); ``data_start``.
    """

    cost: str = "sse"
    init_scale: float = 0.5
    free_masses: bool = False
    mass_init_scale: float | None = None
    noise: float = 0.0
    seed: int = 0
    restarts: int = 0
    step: float = 0.3
    maxfev: int | None = None
    xatol: float = 1e-5
    fatol: float = 1e-11
    stages: tuple[float, ...] = (0.125, 1.0)
    polish_step: float = 0.02
    early_restarts: int = 0
    early_xatol: float = 1e-4
    horizon: float = HORIZON
    fs: float = FS
    data_start: bool = True


@dataclass
class Outcome:
    """Result of one experiment (JSON via :meth:`to_json`)."""

    id: int
    true: dict[str, float]
    identified: dict[str, float]
    max_rel_error: float
    success: bool
    start: dict[str, float]
    stderr: dict[str, float]
    nfev: int
    cost: float
    seconds: float
    identifiable: bool
    extra: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        out = {"id": self.id, "true": self.true, "identified": self.identified,
               "max_rel_error": _num(self.max_rel_error), "success": self.success,
               "start": self.start, "stderr": {k: _num(v) for k, v in self.stderr.items()},
               "nfev": self.nfev, "cost": _num(self.cost), "seconds": round(self.seconds, 4),
               "identifiable": self.identifiable}
        out.update(self.extra)
        return out


def measurement(model: SuspensionModel, exp: Experiment, noise: float = 0.0, seed: int = 0,
                horizon: float = HORIZON, fs: float = FS) -> tuple[Measurement, dict[str, np.ndarray]]:
    """Target curve of ``exp`` (noise std ``noise`` x each channel's std): measured and clean channels."""
    t = time_grid(horizon, fs)
    clean = simulate(model, exp.truth, t, None, exp.x0)
    rng = np.random.default_rng(seed)
    meas = {c: clean[c] + noise * float(np.std(clean[c])) * rng.standard_normal(t.size) if noise > 0
            else clean[c].copy() for c in model.state_names}
    return (Measurement(t=t, road={}, measured=meas, warnings=[], source=f"doe:{model.name}:{exp.id}"),
            {c: clean[c] for c in model.state_names})


def free_names(model: SuspensionModel, free_masses: bool) -> list[str]:
    """Free parameters of a run: all, or all but the masses and inertia."""
    return [p.name for p in model.params if free_masses or p.kind not in ("mass", "inertia")]


def truncate(meas: Measurement, fraction: float) -> Measurement:
    """The first ``fraction`` of a record (at least 10 samples)."""
    n = min(max(10, int(round(fraction * (meas.t.size - 1))) + 1), meas.t.size)
    return Measurement(t=meas.t[:n], road={k: v[:n] for k, v in meas.road.items()},
                       measured={k: v[:n] for k, v in meas.measured.items()},
                       warnings=list(meas.warnings), source=meas.source)


def identify_staged(model: SuspensionModel, meas: Measurement, x0: np.ndarray,
                    params: Parameters, settings: Settings,
                    weights: dict[str, float] | None = None) -> IdentResult:
    """Nelder-Mead in log coordinates with horizon continuation (see :class:`Settings`).

    ``weights`` (channel -> residual factor) default to 1; ``nfev`` is summed over the stages.
    """
    stages = tuple(settings.stages) if settings.stages else (1.0,)
    if stages[-1] != 1.0:
        stages = stages + (1.0,)
    cur = params
    nfev = 0
    res: IdentResult | None = None
    for i, frac in enumerate(stages):
        last = i == len(stages) - 1
        data = meas if frac >= 1.0 else truncate(meas, frac)
        problem = OutputErrorProblem(model, data, cost=settings.cost, x0=x0, weights=weights)
        res, _ = fit(problem, cur, restarts=settings.restarts if last else settings.early_restarts,
                     maxfev=settings.maxfev,
                     step=settings.step if i == 0 else settings.polish_step,
                     with_stderr=last and (settings.noise > 0 or settings.free_masses),
                     xatol=settings.xatol if last else settings.early_xatol, fatol=settings.fatol)
        nfev += res.nfev
        if not last:
            cur = cur.copy()
            for k in cur.free:
                cur[k].value = float(res.params[k])
    if res is None:  # pragma: no cover - stages always ends with 1.0
        raise RuntimeError("no identification stage ran")
    res.nfev = nfev
    return res


def start_parameters(model: SuspensionModel, exp: Experiment, settings: Settings) -> Parameters:
    """The design's known values fixed at the truth, the free ones at their start (see :class:`Settings`)."""
    free = free_names(model, settings.free_masses)
    mass_scale = settings.init_scale if settings.mass_init_scale is None else settings.mass_init_scale
    kind = {p.name: p.kind for p in model.params}
    init = {k: (mass_scale if kind[k] in ("mass", "inertia") else settings.init_scale) * exp.truth[k]
            for k in free}
    return Parameters.for_model(model, fix={k: v for k, v in exp.truth.items() if k not in free},
                                init=init)


def band_of(res: IdentResult, free: list[str]) -> dict[str, tuple[float, float]]:
    """The reported 3-sigma band of each free parameter (honest band, else ``+- 3 stderr``)."""
    bands = res.bands or {}
    return {k: bands[k] if k in bands else
            ((res.params[k] - SIGMAS * res.stderr[k], res.params[k] + SIGMAS * res.stderr[k])
             if math.isfinite(res.stderr[k]) else (math.nan, math.nan)) for k in free}


def joint_region(res: IdentResult, truth: dict[str, float], free: list[str]
                 ) -> dict[str, Any] | None:
    """Whether the truth lies in the row's joint 3-sigma confidence region (``None`` without covariance).

    The region ``d' C^-1 d <= chi2_p(1 - 0.27 %)`` (``d`` the log-parameter error) misses a correct
    truth as often per row as one band per value. Returns ``d2``, ``limit``, ``dof`` and ``inside``.
    """
    if res.cov_log is None or not free:
        return None
    d = np.array([math.log(truth[k] / res.params[k]) if res.params[k] > 0 else math.inf
                  for k in free])
    C = np.asarray(res.cov_log, dtype=float)
    if not (np.isfinite(d).all() and np.isfinite(C).all()):
        return None
    d2 = float(d @ np.linalg.pinv(C, rcond=1e-12, hermitian=True) @ d)
    limit = float(chi2.isf(JOINT_ALPHA, len(free)))
    return {"d2": d2, "limit": limit, "dof": len(free), "inside": bool(d2 <= limit)}



def run_experiment(model: SuspensionModel, exp: Experiment, settings: Settings) -> tuple[Outcome, IdentResult]:
    """Identify one experiment and score it against the truth (cost, scale and noise checked by the CLI)."""
    if settings.mass_init_scale is not None and not (settings.mass_init_scale > 0
                                                     and math.isfinite(settings.mass_init_scale)):
        raise UsageError(f"--mass-init-scale: expected a finite number > 0, got {settings.mass_init_scale}")
    meas, _ = measurement(model, exp, settings.noise, settings.seed + exp.id,
                          settings.horizon, settings.fs)
    free = free_names(model, settings.free_masses)
    params = start_parameters(model, exp, settings)
    init = {k: params[k].value for k in free}
    t0 = time.perf_counter()
    whole = OutputErrorProblem(model, meas, cost=settings.cost, x0=exp.x0)
    # from the data-driven estimate the basin is already found: the whole record at once
    direct = replace(settings, stages=(1.0,))
    res = fit_from_starts(whole, params,
                          lambda start: identify_staged(model, meas, exp.x0, start,
                                                        settings if start is params else direct),
                          data_start=settings.data_start)
    dt = time.perf_counter() - t0
    rel = {k: (res.params[k] - exp.truth[k]) / exp.truth[k] for k in free}
    max_rel = max((abs(v) for v in rel.values()), default=0.0)
    bands = band_of(res, free)
    if settings.noise > 0:
        success = all(0 < bands[k][0] <= exp.truth[k] <= bands[k][1] < math.inf for k in free)
    else:
        success = max_rel <= TOL
    out = Outcome(exp.id, dict(exp.truth), {k: float(v) for k, v in res.params.items()},
                  float(max_rel), bool(success), init, dict(res.stderr), int(res.nfev),
                  float(res.cost), dt, bool(res.identifiable),
                  {"rel_error": {k: float(v) for k, v in rel.items()},
                   "warnings": list(res.warnings),
                   "reported_success": bool(res.success),
                   "band_3sigma": {k: [_num(lo), _num(hi)] for k, (lo, hi) in bands.items()},
                   "band_method": {k: (res.band_method or {}).get(k, "curvature") for k in free},
                   **({"joint_3sigma": joint_region(res, exp.truth, free)}
                      if settings.noise > 0 else {}),
                   **({"starts": res.starts} if res.starts is not None else {})})
    return out, res


def run_design(model: SuspensionModel | str, settings: Settings,
               ids: list[int] | None = None,
               progress: Callable[[int, int, Outcome], None] | None = None) -> dict[str, Any]:
    """Run every (or the listed) experiment of the model's design.

    Returns the contract's object plus ``success_beyond_10x`` (successes with a parameter more
    than 10x off, which must stay empty) and, for noisy designs, ``in_joint_region`` and
    ``band_coverage``.
    """
    if isinstance(model, str):
        model = get_model(model)
    exps = [e for e in experiments(model) if ids is None or e.id in ids]
    rows = []
    for i, e in enumerate(exps):
        o, _ = run_experiment(model, e, settings)
        rows.append(o)
        if progress is not None:
            progress(i + 1, len(exps), o)
    out = {"design": DESIGNS[model.name],
           "experiments": [o.to_json() for o in rows],
           "successes": int(sum(o.success for o in rows)),
           "total": len(rows),
           "success_beyond_10x": [o.id for o in rows if success_beyond(o, FAR_OFF)]}
    if settings.noise > 0:
        out["in_joint_region"] = int(sum(bool((o.extra.get("joint_3sigma") or {}).get("inside"))
                                         for o in rows))
        out["band_coverage"] = band_coverage([o.to_json() for o in rows])
    return out


def band_coverage(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Do a noisy design's bands and joint regions miss their truths as often as correct ones?

    Rows are independent, so the rows outside their joint region are binomial, which ``p_value``
    tests (small: regions, and so bands, too narrow).
    """
    n = missed = 0
    rows_missed: list[int] = []
    for r in rows:
        truth = r.get("true", {})
        row_miss = False
        for k, band in (r.get("band_3sigma") or {}).items():
            lo, hi = band
            if lo is None or hi is None or not (0 < lo < math.inf and hi < math.inf):
                continue
            n += 1
            if not lo <= truth[k] <= hi:
                missed += 1
                row_miss = True
        if row_miss:
            rows_missed.append(int(r["id"]))
    joints = [(int(r["id"]), r["joint_3sigma"]) for r in rows if r.get("joint_3sigma") is not None]
    joint_rows = len(joints)
    joint_outside = [i for i, j in joints if not j["inside"]]
    k = len(joint_outside)
    return {"bands": n, "missed": missed, "expected": round(n * JOINT_ALPHA, 4),
            "rows_missed": rows_missed, "joint_rows": joint_rows, "joint_outside": joint_outside,
            "joint_expected": round(joint_rows * JOINT_ALPHA, 4),
            "p_value": float(binom.sf(k - 1, joint_rows, JOINT_ALPHA)) if k else 1.0}


#: a parameter this far (factor) from the truth must never be part of a success
FAR_OFF = 10.0


def success_beyond(o: Outcome, factor: float) -> bool:
    """Whether ``o`` is a success with a free parameter more than ``factor`` times from the truth."""
    rel = o.extra.get("rel_error", {})
    far = any(not (1.0 / factor <= 1.0 + v <= factor) for v in rel.values())
    return bool(far and (o.success or o.extra.get("reported_success")))
