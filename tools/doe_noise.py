"""Noise study (seed §6.2) and the Cramér–Rao lower bound for the same data.

The seed adds Gaussian noise with std between 0.1 and 0.5 times each noise-free signal's
std and reports the identified parameters' maximum relative error (8.83 % with cost 1,
2.5 % with cost 2, at 0.5 sigma). Here every design row can be repeated over noise seeds:

* per-parameter relative errors (mean, RMS, max over seeds);
* the *denoised* signal — the identified model's simulation from the known initial
  state — and its RMS error against the clean signal, relative to the noise's;
* the Cramér–Rao bound: with white Gaussian noise of known std ``sigma_c`` on channel
  ``c``, the Fisher information of the free log-parameters ``u = log(theta)`` is
  ``F = sum_c sum_k (dy_kc/du)(dy_kc/du)^T / sigma_c^2`` and no unbiased estimator has
  a relative standard deviation below ``sqrt(diag(F^-1))``. The observed RMS relative
  error divided by that bound is the *efficiency ratio* (1 = as good as possible);
* coverage of the run's own 3-sigma band (the contract's noisy success rule): the honest
  band of :mod:`estimator.identify.profile` (``coverage_3sigma``) and the curvature band
  ``value +- 3 stderr`` alone (``coverage_curvature_3sigma``);
* the *linearised estimation error* of one realisation (:func:`linearised_error`): near the
  truth the output-error estimate is linear in the noise, so the error a realisation puts
  into the fit follows from the noise alone, with its exact covariance. A fit that agrees
  with it is at the minimum the noise puts there; a z-score it reproduces is the
  realisation's, not the identifier's.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from estimator.doe.design import Experiment, experiments
from estimator.doe.runner import (SIGMAS, Settings, band_of, free_names, identify_staged,
                                  measurement)
from estimator.identify import OutputErrorProblem, Parameters, jacobian_log
from estimator.identify.profile import apply_bands
from suspid.io.csvio import Measurement
from suspid.models import SuspensionModel, get_model
from suspid.models.base import FloatArray
from suspid.simulate import simulate


def noise_sigmas(clean: dict[str, FloatArray], fraction: float) -> dict[str, float]:
    """Noise std per channel (SI): ``fraction`` x the clean channel's std."""
    return {c: fraction * float(np.std(y)) for c, y in clean.items()}


def fisher_information(model: SuspensionModel, exp: Experiment, free: list[str],
                       channels: list[str], sigma: dict[str, float], t: FloatArray) -> FloatArray:
    """Fisher information of the free log-parameters for white Gaussian channel noise.

    Parameters
    ----------
    model : SuspensionModel
    exp : Experiment
        Truth and the known initial state.
    free : list of str
        Free parameters (the rest are known).
    channels : list of str
        Measured channels the estimator uses.
    sigma : dict
        Noise std per channel (SI units of the channel).
    t : ndarray
        Sample times (s).

    Returns
    -------
    ndarray, shape (len(free), len(free))
        ``F`` in units of 1 / (log-parameter)^2.
    """
    clean = simulate(model, exp.truth, t, None, exp.x0)
    meas = Measurement(t=t, road={}, measured={c: clean[c] for c in channels}, source="crlb")
    w = {c: 1.0 / sigma[c] for c in channels}
    problem = OutputErrorProblem(model, meas, cost="frobenius", x0=exp.x0, weights=w)
    J = jacobian_log(problem, exp.truth, free)  # rows already divided by sigma
    return J.T @ J


def crlb_relative(F: FloatArray) -> FloatArray:
    """Lower bound on the relative std of each free parameter, ``sqrt(diag(F^-1))``."""
    return np.sqrt(np.clip(np.diag(np.linalg.pinv(F, rcond=1e-13)), 0.0, None))


def estimator_channels(model: SuspensionModel, cost: str) -> list[str]:
    """Channels the DoE's cost uses: positions (``sse``) or positions and velocities."""
    return list(model.coords) if cost == "sse" else list(model.state_names)


@dataclass
class LinearisedError:
    """The linear map from a design row's noise to its log-parameter error, at the truth.

    For noise ``e`` on the cost's channels the least-squares estimate's log-parameter error
    is ``delta = (J^T J)^-1 J^T e`` to first order (``J`` the sensitivity of the weighted
    channels to the log-parameters at the truth, :func:`jacobian_log`), with the exact
    covariance ``C = (J^T J)^-1 J^T S J (J^T J)^-1`` (``S`` the per-channel variance of the
    weighted noise the record is made with), so ``delta_k / sqrt(C_kk)`` is a standard
    normal value for every realisation.

    Attributes
    ----------
    free : list of str
        Free parameters (the order of the rows below).
    channels : list of str
        The cost's channels.
    gain : ndarray, shape (n_free, n_samples * n_channels)
        ``(J^T J)^-1 J^T``: log-parameter error (dimensionless) per unit of weighted noise
        (channel units); the noise flattened sample by sample, channels within.
    cov : ndarray, shape (n_free, n_free)
        ``C``, the exact covariance of the log-parameter error (dimensionless).
    sigma : ndarray, shape (n_channels,)
        Each channel's weighted noise std (channel units).
    clean : ndarray, shape (n_samples, n_channels)
        The noise-free channels (channel units).
    weights : ndarray, shape (n_channels,)
        The cost's per-channel weights (dimensionless; 1 in ``suspid doe``).
    """

    free: list[str]
    channels: list[str]
    gain: FloatArray
    cov: FloatArray
    sigma: FloatArray
    clean: FloatArray
    weights: FloatArray

    @property
    def stderr(self) -> FloatArray:
        """The exact standard errors of the log-parameters (dimensionless)."""
        return np.sqrt(np.diag(self.cov))

    def noise_of(self, meas: Measurement) -> FloatArray:
        """The weighted noise of the record ``meas`` (made from this row's clean channels),
        flattened as :attr:`gain`'s columns (channel units)."""
        got = np.column_stack([meas.measured[c] for c in self.channels])
        return np.asarray(((got - self.clean) * self.weights).reshape(-1), dtype=float)

    def delta(self, meas: Measurement) -> FloatArray:
        """The linearised log-parameter error ``(J^T J)^-1 J^T e`` of the record ``meas``
        (dimensionless, ``log(estimate / truth)``)."""
        return np.asarray(self.gain @ self.noise_of(meas), dtype=float)


def linearised_error(model: SuspensionModel, exp: Experiment, settings: Settings
                     ) -> LinearisedError:
    """:class:`LinearisedError` of design row ``exp`` under ``settings`` (its cost, noise
    level, record length and sample rate; the masses fixed unless ``free_masses``).

    The Jacobian is the identifier's own (:func:`jacobian_log`) at the truth, on the
    noise-free record; the noise std of a channel is ``settings.noise`` x its clean std, as
    :func:`measurement` draws it.
    """
    meas, clean = measurement(model, exp, 0.0, 0, settings.horizon, settings.fs)
    problem = OutputErrorProblem(model, meas, cost=settings.cost, x0=exp.x0)
    free = free_names(model, settings.free_masses)
    J = jacobian_log(problem, exp.truth, free)
    gain = np.asarray(np.linalg.solve(J.T @ J, J.T), dtype=float)
    sig = noise_sigmas({c: clean[c] for c in problem.channels}, settings.noise)
    sigma = np.array([sig[c] for c in problem.channels]) * problem.w
    cov = (gain * np.tile(sigma ** 2, problem.t.size)) @ gain.T
    Y = np.column_stack([clean[c] for c in problem.channels])
    return LinearisedError(free, list(problem.channels), gain, cov, sigma, Y,
                           np.asarray(problem.w, dtype=float))


def monte_carlo(model: SuspensionModel | str, exp_id: int, settings: Settings, seeds: int,
                weighted: bool = False,
                progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """Repeat one noisy experiment over ``seeds`` noise realisations.

    Parameters
    ----------
    model : SuspensionModel or str
    exp_id : int
        Design row (1-based).
    settings : Settings
        ``settings.noise`` is the noise fraction; ``settings.seed`` the first seed.
    seeds : int
        Number of noise realisations.
    weighted : bool
        Weight each channel by 1 / its noise std (the maximum-likelihood cost) instead of
        the seed's unweighted cost.

    Returns
    -------
    dict
        Per-parameter ``mean``/``rms``/``max`` relative errors, ``crlb`` relative std,
        ``ratio`` (RMS error / CRLB), ``coverage_3sigma`` (fraction of runs where every
        parameter is inside its 3-sigma band; ``coverage_curvature_3sigma`` for the curvature
        band alone; ``coverage_band`` for the honest band with a side the record does not
        bound taken as open, ``open_band`` the fraction of runs with such a side, i.e.
        reported not identifiable; ``covered_or_flagged``: the truth inside the band or the
        run reported not identifiable), denoising errors and the raw runs.
    """
    if isinstance(model, str):
        model = get_model(model)
    exp = next(e for e in experiments(model) if e.id == exp_id)
    free = free_names(model, settings.free_masses)
    chans = estimator_channels(model, settings.cost)
    _, clean = measurement(model, exp, 0.0, 0, settings.horizon, settings.fs)
    sig = noise_sigmas(clean, settings.noise)
    t = np.arange(next(iter(clean.values())).size) / settings.fs
    F = fisher_information(model, exp, free, chans, sig, t)
    bound = crlb_relative(F)
    runs: list[dict[str, Any]] = []
    for i in range(seeds):
        seed = settings.seed + 1000 * i + exp.id
        meas, _ = measurement(model, exp, settings.noise, seed, settings.horizon, settings.fs)
        fix = {k: v for k, v in exp.truth.items() if k not in free}
        init = {k: settings.init_scale * exp.truth[k] for k in free}
        params = Parameters.for_model(model, fix=fix, init=init)
        weights = {c: 1.0 / sig[c] for c in chans} if weighted else None
        res = identify_staged(model, meas, exp.x0, params, settings, weights=weights)
        rel = {k: (res.params[k] - exp.truth[k]) / exp.truth[k] for k in free}
        curvature = all(math.isfinite(res.stderr[k]) and
                        abs(res.params[k] - exp.truth[k]) <= SIGMAS * res.stderr[k] for k in free)
        apply_bands(OutputErrorProblem(model, meas, cost=settings.cost, x0=exp.x0,
                                       weights=weights), res, free)
        bands = band_of(res, free)
        covered = all(bands[k][0] <= exp.truth[k] <= bands[k][1] for k in free)
        closed = all(0 < bands[k][0] and bands[k][1] < math.inf for k in free)
        inside = covered and closed
        den = simulate(model, res.params, t, None, exp.x0)
        denoise = {c: float(np.sqrt(np.mean((den[c] - clean[c]) ** 2)) / sig[c]) for c in chans}
        runs.append({"seed": seed, "rel_error": rel, "inside_3sigma": inside,
                     "inside_curvature_3sigma": curvature, "inside_band": covered,
                     "band_closed": closed, "identifiable": bool(res.identifiable),
                     "band_method": dict(res.band_method or {}),
                     "stderr_rel": {k: res.stderr[k] / exp.truth[k] for k in free},
                     "denoised_rms_over_noise": denoise, "nfev": res.nfev})
        if progress is not None:
            progress(i + 1, seeds)
    E = np.array([[r["rel_error"][k] for k in free] for r in runs])
    rms = np.sqrt(np.mean(E ** 2, axis=0))
    out = {
        "model": model.name, "experiment": exp.id, "cost": settings.cost,
        "weighted": weighted, "noise": settings.noise, "seeds": seeds, "free": free,
        "channels": chans,
        "mean": dict(zip(free, E.mean(axis=0).tolist())),
        "rms": dict(zip(free, rms.tolist())),
        "max_abs": dict(zip(free, np.max(np.abs(E), axis=0).tolist())),
        "max_abs_overall": float(np.max(np.abs(E))),
        "crlb": dict(zip(free, bound.tolist())),
        "ratio": dict(zip(free, (rms / bound).tolist())),
        "mean_stderr_rel": {k: float(np.mean([r["stderr_rel"][k] for r in runs])) for k in free},
        "coverage_3sigma": float(np.mean([r["inside_3sigma"] for r in runs])),
        "coverage_curvature_3sigma": float(np.mean([r["inside_curvature_3sigma"] for r in runs])),
        "coverage_band": float(np.mean([r["inside_band"] for r in runs])),
        "open_band": float(np.mean([not r["band_closed"] for r in runs])),
        "covered_or_flagged": float(np.mean([r["inside_band"] or not r["identifiable"]
                                             for r in runs])),
        "denoised_rms_over_noise": {c: float(np.mean([r["denoised_rms_over_noise"][c] for r in runs]))
                                    for c in chans},
        "runs": runs,
    }
    return out
