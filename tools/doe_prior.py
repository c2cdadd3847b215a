"""Identifiability study: the scale ambiguity and the minimal prior knowledge.

For the linear models every mass, damping and stiffness enters ``A = [[0, I], [-M^-1 K,
-M^-1 C]]`` (and the road input) only through ``M^-1``-ratios, so multiplying all of them
by one factor leaves the response unchanged: the seed's "-40 %" answers of the
unrestricted optimisation. The lengths ``a1``, ``a2`` are not scaled. One known
parameter of the scaled group removes that single direction; whether it is *enough*
(no other flat direction) is checked here numerically with the singular values of the
output sensitivity at the truth and with an actual fit from 0.5x the truth.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from estimator.doe.design import Experiment, experiments, time_grid
from estimator.doe.runner import TOL, Settings, identify_staged, measurement
from estimator.identify import OutputErrorProblem, Parameters, jacobian_log
from suspid.models import SuspensionModel, get_model
from suspid.simulate import simulate


def scale_ambiguity(model: SuspensionModel | str, exp_id: int, factor: float = 0.6,
                    settings: Settings | None = None) -> dict[str, Any]:
    """Show that scaling every mass, damping and stiffness by ``factor`` changes nothing.

    Returns the largest absolute and relative difference of the two responses over all
    channels (positions, velocities, accelerations).
    """
    model = get_model(model) if isinstance(model, str) else model
    settings = settings or Settings()
    exp = _exp(model, exp_id)
    t = time_grid(settings.horizon, settings.fs)
    scaled = {k: v * factor if k in model.scale_invariant else v for k, v in exp.truth.items()}
    a = simulate(model, exp.truth, t, None, exp.x0)
    b = simulate(model, scaled, t, None, exp.x0)
    diff = max(float(np.max(np.abs(a[c] - b[c]))) for c in model.channels)
    rel = max(float(np.max(np.abs(a[c] - b[c])) / max(np.max(np.abs(a[c])), 1e-300))
              for c in model.channels)
    return {"model": model.name, "experiment": exp.id, "factor": factor,
            "scaled_params": list(model.scale_invariant), "max_abs_diff": diff,
            "max_rel_diff": rel}


def _exp(model: SuspensionModel, exp_id: int) -> Experiment:
    for e in experiments(model):
        if e.id == exp_id:
            return e
    raise ValueError(f"model {model.name} has no experiment {exp_id}")


def sensitivity_singular_values(model: SuspensionModel, exp: Experiment, free: list[str],
                                settings: Settings) -> list[float]:
    """Relative singular values (largest = 1) of the channel-normalised log-sensitivity."""
    meas, clean = measurement(model, exp, 0.0, 0, settings.horizon, settings.fs)
    w = {c: 1.0 / max(float(np.std(clean[c])), 1e-300) for c in model.state_names}
    problem = OutputErrorProblem(model, meas, cost="frobenius", x0=exp.x0, weights=w)
    J = jacobian_log(problem, exp.truth, free)
    s = np.linalg.svd(J, compute_uv=False)
    return (s / s[0]).tolist()


def prior_study(model: SuspensionModel | str, exp_id: int, known: list[str],
                settings: Settings | None = None, mass_start: float = 1.0) -> dict[str, Any]:
    """Fit with only ``known`` parameters fixed at the truth.

    Free masses and inertia start at ``mass_start`` x the truth (the seed started them at
    the truth), every other free parameter at ``settings.init_scale`` x the truth.

    Returns the identified parameters, relative errors, the identifier's identifiability
    verdict and warnings, the sensitivity singular values at the truth and ``success``
    (every free parameter within 1 %).
    """
    model = get_model(model) if isinstance(model, str) else model
    settings = settings or Settings()
    exp = _exp(model, exp_id)
    free = [k for k in model.param_names if k not in known]
    meas, _ = measurement(model, exp, 0.0, 0, settings.horizon, settings.fs)
    kinds = {p.name: p.kind for p in model.params}
    init = {k: (mass_start if kinds[k] in ("mass", "inertia") else settings.init_scale)
            * exp.truth[k] for k in free}
    params = Parameters.for_model(model, fix={k: exp.truth[k] for k in known}, init=init)
    s = Settings(**{**settings.__dict__, "free_masses": True})  # stderr + identifiability
    res = identify_staged(model, meas, exp.x0, params, s)
    rel = {k: (res.params[k] - exp.truth[k]) / exp.truth[k] for k in free}
    sv = sensitivity_singular_values(model, exp, free, settings)
    scaled = [k for k in free if k in model.scale_invariant]
    ratios = np.array([res.params[k] / exp.truth[k] for k in scaled])
    common = float(np.exp(np.mean(np.log(ratios)))) if ratios.size else 1.0
    spread = float(np.max(np.abs(ratios / common - 1.0))) if ratios.size else 0.0
    return {"common_factor": common, "spread_about_common_factor": spread,"model": model.name, "experiment": exp.id, "known": known, "free": free,
            "identified": res.params, "rel_error": rel,
            "max_rel_error": max(abs(v) for v in rel.values()),
            "success": max(abs(v) for v in rel.values()) <= TOL,
            "identifiable": res.identifiable, "warnings": res.warnings,
            "min_singular_value": min(sv), "singular_values": sv, "nfev": res.nfev}
