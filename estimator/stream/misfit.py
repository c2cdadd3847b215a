"""Windows whose fit leaves far more than white noise: the model or a fixed value is wrong.

:class:`MisfitWatch` marks a window whose ``noise_floor_ratio`` exceeds :data:`MISFIT_RATIO`
in a channel that also misses more than ``MISFIT_SHARE`` of its signal (as ``suspid identify``
judges it), and warns once when :data:`MISFIT_WINDOWS` in a row do (``docs/monitoring.md``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from estimator.identify.misfit import MISFIT_SHARE
from estimator.stream.events import Notice
from suspid.models.base import FloatArray

#: noise-floor ratio above which a window's fit is a misfit, above every correct fit measured
#: with ``tools/misfit_floor.py``
MISFIT_RATIO = 12.0
#: consecutive fitted windows above ``MISFIT_RATIO`` before the warning
MISFIT_WINDOWS = 3


def misfit_shares(ratios: Mapping[str, float], rms: Mapping[str, float],
                  data: Mapping[str, FloatArray]) -> dict[str, float]:
    """Per fitted channel: its residual's excess over the noise floor, ``rms^2 (1 - 1/ratio)``,
    as a share of the fitted channels' summed variance in the window (``inf`` when they do
    not move), as :func:`estimator.identify.misfit.misfit_measures` forms it."""
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
    """Mark misfit windows and warn once, naming the ``fixed`` values, when they persist."""

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
        """One fitted window ending at ``t`` (s) with its per-channel ratios and ``shares``
        (:func:`misfit_shares`). Returns whether it is a misfit, and the warning when it
        makes the misfit persistent for the first time."""
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
        return True, Notice(t, "misfit", msg, {"ratio": ratio, "channels": {c: self.worst[c] for c in chans},
                                               "windows": self.run, "since": self.since,
                                               "threshold": self.threshold, "fixed": dict(self.fixed)})
