"""Parameter tracking with uncertainty: a random-walk Kalman filter over window estimates.

Each parameter ``theta`` is tracked as ``l = log(theta)`` (relative changes, positive
values). Between two window estimates ``dt`` apart the track's variance grows by
``q^2 dt`` (``q``: the relative drift allowed per sqrt(second), default 0.01/sqrt(s), i.e.
about 1 % in a second, 8 % in a minute of random walk); a window estimate with relative
standard error ``s`` updates it with variance ``s^2 * overlap`` where ``overlap =
window / step`` accounts for windows sharing data (their errors are correlated, so they
count as ``1 / overlap`` independent looks each). Skipped windows only let the variance grow.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping


@dataclass
class _Track:
    l: float
    var: float
    t: float


@dataclass
class ParameterTracker:
    """Per-parameter random-walk Kalman filter in log space.

    Parameters
    ----------
    q : float
        Relative random-walk intensity (1/sqrt(s)).
    overlap : float
        Measurement-variance inflation for overlapping windows (``window / step``).
    """

    q: float = 0.01
    overlap: float = 1.0
    tracks: dict[str, _Track] = field(default_factory=dict)

    def update(self, t: float, values: Mapping[str, float], stderr: Mapping[str, float]
               ) -> dict[str, dict[str, float]]:
        """Fold in one window estimate; returns ``name -> {"value", "stderr"}`` (SI)."""
        out: dict[str, dict[str, float]] = {}
        for k, se in stderr.items():
            v = values[k]
            if not (v > 0 and math.isfinite(v) and math.isfinite(se) and se > 0):
                continue
            r = (se / v) ** 2 * self.overlap
            tr = self.tracks.get(k)
            if tr is None:
                tr = self.tracks[k] = _Track(math.log(v), r, t)
            else:
                var = tr.var + self.q ** 2 * max(t - tr.t, 0.0)
                gain = var / (var + r)
                tr.l += gain * (math.log(v) - tr.l)
                tr.var = (1 - gain) * var
                tr.t = t
            val = math.exp(tr.l)
            out[k] = {"value": val, "stderr": val * math.sqrt(tr.var)}
        return out
