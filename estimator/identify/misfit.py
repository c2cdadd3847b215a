"""How well a fit explains the record: the noise-floor ratio and the misfit statistics.

The residual of a fit at the noise floor is white measurement noise; a misfit (a local
minimum, a value held wrong, an effect the model lacks) is smooth at the sampling rate.
"""
from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from estimator.identify.problem import OutputErrorProblem
from suspid.models.base import FloatArray

#: normalised output-error cost below which a fit explains the record exactly (noise-free)
EXACT_FIT = 1e-10
#: :func:`noise_floor_ratio` up to which a noisy fit counts as at the noise floor (clean fits
#: measure 0.97-1.04, local minima 1.8-19: docs/performance.md)
NOISE_FLOOR = 1.15
#: a fitted channel's noise-floor ratio above which the fit is a misfit (docs/robustness.md)
MISFIT_FLOOR = 2.0
#: share of the record's signal the residual's excess over its noise floor must exceed as
#: well for a misfit (a noise-free record has no noise floor)
MISFIT_SHARE = 1e-5


def noise_floor_ratio(problem: OutputErrorProblem, p: Mapping[str, float]) -> float:
    """Weighted sum of squares of the residual over what white noise alone would give.

    Each channel's noise variance comes from the residual's differences
    (``mean(diff(r)^2) / 2``), which white noise passes and a smooth misfit hardly enters:
    about 1 at the noise floor, above it by the misfit's share; ``inf`` where not defined.
    """
    parts = noise_floor_parts(problem, p)
    if parts is None:
        return math.inf
    num = sum(a for a, _ in parts.values())
    den = sum(b for _, b in parts.values())
    if not (den > 0 and math.isfinite(num)):
        return math.inf
    return num / den


def noise_floor_ratios(problem: OutputErrorProblem, p: Mapping[str, float]) -> dict[str, float]:
    """:func:`noise_floor_ratio` of every fitted channel on its own (empty when the prediction fails)."""
    parts = noise_floor_parts(problem, p)
    return {} if parts is None else ratios_of_parts(parts)


def ratios_of_parts(parts: Mapping[str, tuple[float, float]]) -> dict[str, float]:
    """Channel -> ratio from :func:`noise_floor_parts` (``inf`` where it cannot be formed)."""
    return {c: (a / b if b > 0 and math.isfinite(a) else math.inf) for c, (a, b) in parts.items()}


def noise_floor_parts(problem: OutputErrorProblem, p: Mapping[str, float]
                      ) -> dict[str, tuple[float, float]] | None:
    """Per fitted channel: the residual's sum of squares and what white noise would give.

    Channels with fewer than 3 finite residuals are left out; ``None`` when the prediction fails.
    """
    try:
        r = problem.predict(p).residual
    except (np.linalg.LinAlgError, ValueError, FloatingPointError):
        return None
    return residual_noise_floor_parts(r, problem.channels)


def residual_noise_floor_parts(r: FloatArray, channels: Sequence[str]
                               ) -> dict[str, tuple[float, float]]:
    """:func:`noise_floor_parts` of a residual ``r`` (samples x ``channels``, NaN where missing)."""
    out: dict[str, tuple[float, float]] = {}
    for j, c in enumerate(channels):
        rj = r[:, j]
        rj = rj[np.isfinite(rj)]
        if rj.size < 3:
            continue
        d = np.diff(rj)
        out[c] = (float(rj @ rj), float(d @ d) / 2.0 * rj.size / d.size)
    return out


def misfit_measures(problem: OutputErrorProblem, p: Mapping[str, float]
                    ) -> dict[str, tuple[float, float]]:
    """Per fitted channel: its noise-floor ratio and the excess's share of the signal.

    The share is the residual's sum of squares less its noise floor over the fitted
    channels' summed sums of squares about their means, weighted as in the cost. Empty when
    the prediction fails or the record does not move.
    """
    parts = noise_floor_parts(problem, p)
    if parts is None:
        return {}
    var = 0.0
    for j in range(len(problem.channels)):
        y = problem.Ymeas[:, j]
        y = y[np.isfinite(y)]
        if y.size:
            var += float(np.sum((y - y.mean()) ** 2)) * float(problem.w[j]) ** 2
    if not var > 0:
        return {}
    out: dict[str, tuple[float, float]] = {}
    for j, c in enumerate(problem.channels):
        if c in parts and math.isfinite(parts[c][0]):
            a, b = parts[c]
            out[c] = (a / b if b > 0 else math.inf, (a - b) * float(problem.w[j]) ** 2 / var)
    return out


def misfit_channels(problem: OutputErrorProblem, p: Mapping[str, float]
                    ) -> dict[str, tuple[float, float]]:
    """Fitted channels whose residual at ``p`` (every parameter, SI) is clearly more than
    measurement noise, ``channel -> (ratio, share)``: a noise-floor ratio above
    ``MISFIT_FLOOR`` and an excess above ``MISFIT_SHARE`` of the signal (:func:`misfit_measures`).
    """
    return {c: (r, sh) for c, (r, sh) in misfit_measures(problem, p).items()
            if r > MISFIT_FLOOR and sh > MISFIT_SHARE}


def misfit_warning(misfit: Mapping[str, tuple[float, float]], fixed: Mapping[str, float]
                   ) -> str:
    """The one-line warning of a misfit (:func:`misfit_channels`), naming the held values."""
    chans = ", ".join(f"{c} (noise-floor ratio {r:.3g}, {100.0 * sh:.3g} % of the signal)"
                      for c, (r, sh) in misfit.items())
    held = ", ".join(f"{k}={v:.6g}" for k, v in fixed.items())
    cause = (f"likely causes: a value held fixed ({held}: --fix), an effect the model lacks "
             "(suspid diagnose) or a faulty channel" if held
             else "likely causes: a local minimum, an effect the model lacks (suspid diagnose) "
                  "or a faulty channel")
    return (f"misfit: the fit leaves far more than measurement noise on {chans}; the model "
            f"does not explain the record; {cause}")
