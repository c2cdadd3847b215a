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

#: normalised output-error cost below which a fit explains the record exactly (noise-free):
#: no other start can do better, so a further start is skipped. Any noisy record stays
#: above it, and there the estimate is biased (its regressors are the noisy channels
#: themselves: errors in variables) and may lead to a local minimum, so the given start runs
#: as well and the lower cost wins, unless the fit leaves only white noise (``NOISE_FLOOR``).
EXACT_FIT = 1e-10

#: :func:`noise_floor_ratio` up to which a fit to a noisy record counts as at the noise floor:
#: its residual is white noise, no other start can lower the cost by more than the noise's
#: own scatter, so a further start is skipped as for an exact fit. Fits at the floor measure
#: 0.97-1.04 on the seed's designs at 0.1-0.5 sigma; the local minima a biased estimate led
#: to measure 1.8-19.
NOISE_FLOOR = 1.15

#: :func:`noise_floor_ratio` of a fitted channel above which the fit of
#: :func:`fit_from_starts` is a misfit, not a success (:func:`misfit_channels`): the smooth,
#: non-white part of its residual at least equals the noise. Correct fits to ``suspid
#: simulate`` records (5 s at 200 Hz; quarter1, quarter2, half4, bump and ISO 8608 roads,
#: noise 0.1 and 0.5 of each channel's std) measure 0.99-1.06; every spring and damper (with
#: full7 the noise-free bump only) held at twice the truth 2.2-52 at 0.1-0.5 sigma (except
#: four at 0.5 sigma: 1.1-1.9, which the noise hides) and 777-1340 noise-free; the half
#: car's body mass at twice the truth (the rest free) 2.8-3.4 at 0.1 sigma (``python
#: tools/identify_misfit.py --can``).
MISFIT_FLOOR = 2.0
#: share of the record's signal (the fitted channels' sums of squares about their means,
#: weighted as in the cost) that a channel residual's excess over its noise floor must
#: exceed as well: a noise-free record has no noise floor (its ratio compares rounding
#: errors: 1.0-1.5, quantized as a CAN log too, but 553 on the full car's bump), and there
#: a correct fit leaves at
#: most 1e-20 (1.1e-8 quantized), while a quarter car's body mass held at twice the truth
#: with its springs and dampers free leaves 1.3e-5 (bump) and 6.7e-4 (ISO road), every
#: spring and damper at twice the truth 0.01-0.26 (same command).
MISFIT_SHARE = 1e-5


def noise_floor_ratio(problem: OutputErrorProblem, p: Mapping[str, float]) -> float:
    """Weighted sum of squares of the residual over what white noise alone would give.

    The noise variance of every channel is estimated from the residual itself, from its
    sample-to-sample differences (``mean(diff(r)^2) / 2``): white measurement noise passes
    them unchanged, while a misfit (a local minimum, a biased estimate) is a response of the
    model, smooth at the sampling rate, and hardly enters them. The ratio is therefore about
    1 (within a few ``sqrt(2 / N)``) for a fit at the noise floor, and above it by the
    misfit's share of the residual otherwise. ``inf`` where it cannot be evaluated.
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
    """:func:`noise_floor_ratio` of every fitted channel on its own (channel -> ratio).

    ``inf`` for a channel where it cannot be evaluated; empty when the prediction fails.
    """
    parts = noise_floor_parts(problem, p)
    return {} if parts is None else ratios_of_parts(parts)


def ratios_of_parts(parts: Mapping[str, tuple[float, float]]) -> dict[str, float]:
    """Channel -> ratio from :func:`noise_floor_parts` (``inf`` where it cannot be formed)."""
    return {c: (a / b if b > 0 and math.isfinite(a) else math.inf) for c, (a, b) in parts.items()}


def noise_floor_parts(problem: OutputErrorProblem, p: Mapping[str, float]
                      ) -> dict[str, tuple[float, float]] | None:
    """Per fitted channel: the residual's sum of squares and what white noise would give.

    The second is ``sum(diff(r)^2) / 2`` scaled to the residual's length (same units
    squared as the channel); channels with fewer than 3 finite residuals are left out.
    ``None`` when the prediction fails.
    """
    try:
        r = problem.predict(p).residual
    except (np.linalg.LinAlgError, ValueError, FloatingPointError):
        return None
    return residual_noise_floor_parts(r, problem.channels)


def residual_noise_floor_parts(r: FloatArray, channels: Sequence[str]
                               ) -> dict[str, tuple[float, float]]:
    """:func:`noise_floor_parts` of a given residual ``r`` (samples x channels, NaN where
    missing; ``channels`` names its columns)."""
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

    The ratio is :func:`noise_floor_ratios`' (``inf`` with no noise floor at all); the
    share is the channel residual's sum of squares less its noise floor over the fitted
    channels' summed sums of squares about their means (weighted as in the cost;
    dimensionless; below 0 when the residual is all noise). A channel the record hardly
    moves (the roll of a symmetric bump) thus weighs what it weighs in the cost. Channels
    with fewer than 3 finite samples are left out; empty when the prediction fails or the
    record does not move.
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
    """Fitted channels whose residual at ``p`` is clearly more than measurement noise.

    A channel is a misfit when its noise-floor ratio exceeds ``MISFIT_FLOOR`` and the
    residual's excess over the noise floor exceeds ``MISFIT_SHARE`` of the record's signal
    (:func:`misfit_measures`). A fit at the noise floor (ratio about 1) or one that
    leaves a negligible part of the signal (a noise-free or quantized record fitted well) is
    none.

    Parameters
    ----------
    problem : OutputErrorProblem
        The record and cost.
    p : mapping
        Every parameter's value (SI).

    Returns
    -------
    dict
        Channel -> ``(ratio, share)`` of the misfit channels (both dimensionless); empty
        when there is no misfit or the prediction fails.
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
