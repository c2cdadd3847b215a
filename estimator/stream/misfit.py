"""Windows whose fit leaves far more than white noise: the model or a fixed value is wrong.

Every fitted window reports, per fitted channel, its residual over what white measurement
noise alone would leave (``noise_floor_ratio``,
:func:`estimator.identify.misfit.noise_floor_ratios`: the residual's sum of squares over half
the sum of its squared sample-to-sample differences). A fit at the noise floor measures
about 1; a model that cannot follow the data (a ``--fix`` value far from the truth, an effect
the model lacks, a faulty sensor) leaves a smooth misfit that raises it. :class:`MisfitWatch`
marks every window above ``MISFIT_RATIO`` as a misfit and, when ``MISFIT_WINDOWS`` fitted
windows in a row are, says so once: a :class:`~estimator.stream.events.Notice` of kind
``misfit`` naming the ratio, the channels and the likely causes. The threshold lies above
every correct fit measured (``tools/misfit_floor.py``, ``docs/monitoring.md``).

A noise-free (or finely quantized) record has no noise floor: its ratio compares rounding
errors and the window's interpolation error, and runs to 20-800 on fits that leave a
millionth of the signal. So, as ``suspid identify`` judges a misfit
(:func:`estimator.identify.misfit.misfit_channels`), a channel counts only when its residual's
excess over the noise floor is also more than ``MISFIT_SHARE`` of the window's signal
(:func:`misfit_shares`); the two verdicts then agree on the same record.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from estimator.identify.misfit import MISFIT_SHARE
from estimator.stream.events import Notice
from suspid.models.base import FloatArray

#: noise-floor ratio above which a window's fit counts as a misfit (dimensionless), set above
#: every correct fit measured with ``tools/misfit_floor.py`` (docs/monitoring.md): records of
#: ``suspid simulate`` with noise 0.1-0.5 of each channel's std, every model, at most 1.4;
#: the damper-wear streams (quantized as the DBC sends them, noise on the road too) 1.5-1.8 on
#: quarter2 and half4, and on quarter1 up to 13.8 in one window and 7.4 in three in a row:
#: the road velocity's noise drives its body through the damper directly and leaves a smooth
#: residual that the differences do not see as noise. A body mass held at twice the truth
#: measures 15-21 (quarter2, 2 % noise) to 50-290 (the wear stream).
MISFIT_RATIO = 12.0
#: consecutive fitted windows above ``MISFIT_RATIO`` before the warning (a persistent misfit,
#: not one window disturbed by a pothole or a burst of lost frames)
MISFIT_WINDOWS = 3


def misfit_shares(ratios: Mapping[str, float], rms: Mapping[str, float],
                  data: Mapping[str, FloatArray]) -> dict[str, float]:
    """Per fitted channel: its residual's excess over the noise floor as a share of the
    window's signal (dimensionless), as :func:`estimator.identify.misfit.misfit_measures`
    forms it for ``identify``.

    Parameters
    ----------
    ratios : mapping
        Channel -> noise-floor ratio of the window's fit (the fitted channels).
    rms : mapping
        Channel -> RMS residual of the fit (channel units).
    data : mapping
        Channel -> the window's samples (NaN where missing).

    Returns
    -------
    dict
        Channel -> ``rms^2 (1 - 1/ratio)`` over the fitted channels' summed mean squares
        about their means; ``inf`` when the window's fitted channels do not move (every
        share of a still record counts); channels without an RMS are left out.
    """
    var = 0.0
    for c in ratios:
        y = np.asarray(data.get(c, ()), dtype=float)
        y = y[np.isfinite(y)]
        if y.size:
            var += float(np.mean((y - y.mean()) ** 2))
    out: dict[str, float] = {}
    for c, r in ratios.items():
        e = rms.get(c, math.nan)
        if not math.isfinite(e):
            continue
        excess = e * e * (1.0 - 1.0 / r) if r > 0 and math.isfinite(r) else e * e
        out[c] = excess / var if var > 0 else math.inf
    return out


@dataclass
class MisfitWatch:
    """Mark misfit windows and warn once when they persist.

    Parameters
    ----------
    fixed : mapping
        Parameters held by ``--fix`` and their values (SI), named in the warning.
    threshold : float
        ``MISFIT_RATIO``.
    windows : int
        ``MISFIT_WINDOWS``.
    """

    fixed: Mapping[str, float] = field(default_factory=dict)
    threshold: float = MISFIT_RATIO
    windows: int = MISFIT_WINDOWS
    run: int = 0
    since: float = math.nan
    worst: dict[str, float] = field(default_factory=dict)
    warned: bool = False
    count: int = 0

    def update(self, t: float, ratios: Mapping[str, float],
               shares: Mapping[str, float] | None = None) -> tuple[bool, Notice | None]:
        """One fitted window ending at ``t`` (s) with its per-channel ratios.

        ``shares`` (:func:`misfit_shares`), when given, holds each channel's excess over
        its noise floor as a share of the window's signal: a channel whose share is at most
        ``MISFIT_SHARE`` is no misfit whatever its ratio (a noise-free record fitted well).
        Returns whether the window is a misfit, and the warning when this window makes the
        misfit persistent for the first time (``None`` otherwise).
        """
        over = {c: float(r) for c, r in ratios.items() if not r <= self.threshold
                and (shares is None or not shares.get(c, math.inf) <= MISFIT_SHARE)}
        if not over:
            self.run = 0
            self.worst = {}
            return False, None
        self.count += 1
        if self.run == 0:
            self.since = t
        self.run += 1
        for c, r in over.items():
            self.worst[c] = max(self.worst.get(c, 0.0), r)
        if self.warned or self.run < self.windows:
            return True, None
        self.warned = True
        return True, self._notice(t)

    def _notice(self, t: float) -> Notice:
        chans = sorted(self.worst, key=lambda c: -self.worst[c])
        ratio = self.worst[chans[0]]
        shown = ", ".join(f"{c} {self.worst[c]:.3g}x" for c in chans)
        fixed = ", ".join(f"{k}={v:g}" for k, v in self.fixed.items())
        causes = (f"a wrong --fix value (held: {fixed})" if fixed else "a wrong --fix value")
        msg = (f"the window fits persistently leave far more than white noise: residual "
               f"{shown} the noise floor in {self.run} windows in a row since t={self.since:.2f} s "
               f"(correct fits stay below {self.threshold:g}); the model does not describe the "
               f"data. Likely causes: {causes}, an effect the model lacks (run `suspid "
               f"diagnose` on a stretch of the data), or a faulty sensor channel. Estimates "
               f"marked misfit are not to be trusted")
        return Notice(t, "misfit", msg, {"ratio": ratio, "channels": {c: self.worst[c] for c in chans},
                                         "windows": self.run, "since": self.since,
                                         "threshold": self.threshold, "fixed": dict(self.fixed)})
