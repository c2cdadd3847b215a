"""Parameter tracking with a trend: a local-linear-trend Kalman filter over window estimates.

Each monitored parameter has a state ``[v, r]`` -- its value (SI) and its rate of change
(SI/s) -- at the data time of the last estimate. Between estimates ``dt`` apart the state
moves as ``v += r dt`` and picks up process noise scaled by the nominal value ``N``: a
level random walk ``(q_level N)^2 dt`` (sudden small changes) and an integrated rate random
walk ``(q_rate N)^2 [[dt^3/3, dt^2/2], [dt^2/2, dt]]`` (wear that starts, speeds up or stops).

A window estimate ``y +/- s`` ending at ``t`` describes the parameter over the window, i.e.
near its middle ``t - lag`` (``lag = window / 2`` for the sliding window; 0 for the EKF,
whose state refers to its last sample): it is folded in with ``y = v(t) - lag r(t)``, so the
tracked value refers to the window's *end* and no longer lags a drifting parameter by half
a window. Windows that share data have correlated errors: the measurement variance is
``s^2 x overlap`` (``overlap = window / step``). Skipped windows only let the variance grow.

The alerts (:class:`estimator.alerts.AlertEngine`) are decided on the tracked value and its
standard error, the forecasts (:class:`estimator.alerts.ForecastEngine`) on the trend
(:meth:`TrendTracker.trends`).

Defaults (``q_level = 0.002 /sqrt(s)``, ``q_rate = 3e-4 /s/sqrt(s)``, prior rate
uncertainty ``0.01 N/s``) measured on the damper-wear streams of
``tools/bench_maintenance.py`` (docs/monitoring.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from estimator.alerts.forecast import Trend


@dataclass
class _Track:
    x: np.ndarray       # [value, rate] (SI, SI/s)
    P: np.ndarray       # 2x2 covariance
    t: float
    nominal: float


@dataclass
class TrendTracker:
    """Per-parameter local-linear-trend Kalman filter (see the module docstring).

    Parameters
    ----------
    q_level : float
        Level random walk, relative to nominal per sqrt(s).
    q_rate : float
        Rate random walk, relative to nominal per s per sqrt(s).
    rate0 : float
        Prior standard deviation of the rate, relative to nominal per s.
    lag : float
        Data time (s) between a window's end and the time its estimate describes.
    overlap : float
        Measurement-variance inflation for overlapping windows (``window / step``).
    nominal : dict, optional
        ``parameter -> nominal`` (SI) scaling the noise; a parameter without one is scaled by
        its first estimate.
    """

    q_level: float = 0.002
    q_rate: float = 3e-4
    rate0: float = 0.01
    lag: float = 0.0
    overlap: float = 1.0
    nominal: dict[str, float] = field(default_factory=dict)
    tracks: dict[str, _Track] = field(default_factory=dict)

    def _predict(self, tr: _Track, t: float) -> None:
        dt = max(t - tr.t, 0.0)
        if dt == 0.0:
            return
        F = np.array([[1.0, dt], [0.0, 1.0]])
        n2 = tr.nominal * tr.nominal
        qr = self.q_rate ** 2 * n2
        Q = qr * np.array([[dt ** 3 / 3.0, dt * dt / 2.0], [dt * dt / 2.0, dt]])
        Q[0, 0] += self.q_level ** 2 * n2 * dt
        tr.x = F @ tr.x
        tr.P = F @ tr.P @ F.T + Q
        tr.t = t

    def update(self, t: float, values: Mapping[str, float], stderr: Mapping[str, float]
               ) -> dict[str, dict[str, float]]:
        """Fold in one window estimate ending at ``t`` (s).

        Returns
        -------
        dict
            ``parameter -> {"value", "stderr", "rate", "rate_stderr"}`` (SI, SI/s) at ``t``.
        """
        for k, se in stderr.items():
            v = values.get(k)
            if v is None or not (math.isfinite(v) and math.isfinite(se) and se > 0):
                continue
            r = se * se * self.overlap
            tr = self.tracks.get(k)
            if tr is None:
                nom = self.nominal.get(k) or abs(v) or 1.0
                tr = self.tracks[k] = _Track(np.array([float(v), 0.0]),
                                             np.diag([r, (self.rate0 * nom) ** 2]), t, nom)
                # the first estimate describes t - lag: move the level to t with the prior rate
                tr.P[0, 0] += (self.lag * self.rate0 * nom) ** 2
                continue
            self._predict(tr, t)
            H = np.array([1.0, -self.lag])
            S = float(H @ tr.P @ H) + r
            K = (tr.P @ H) / S
            tr.x = tr.x + K * (float(v) - float(H @ tr.x))
            tr.P = tr.P - np.outer(K, H @ tr.P)
            tr.P = 0.5 * (tr.P + tr.P.T)
        return self.state(t)

    def state(self, t: float | None = None) -> dict[str, dict[str, float]]:
        """The tracked values at ``t`` (default: each track's last update), JSON-ready."""
        out: dict[str, dict[str, float]] = {}
        for k, tr in self.trends(t).items():
            out[k] = {"value": tr.value, "stderr": tr.value_stderr, "rate": tr.rate,
                      "rate_stderr": tr.rate_stderr}
        return out

    def trends(self, t: float | None = None) -> dict[str, Trend]:
        """Each track as a :class:`~estimator.alerts.forecast.Trend` at ``t``."""
        out: dict[str, Trend] = {}
        for k, tr in self.tracks.items():
            if t is not None and t > tr.t:
                self._predict(tr, t)
            n2 = tr.nominal * tr.nominal
            out[k] = Trend(tr.t, float(tr.x[0]), float(tr.x[1]), float(tr.P[0, 0]),
                           float(tr.P[0, 1]), float(tr.P[1, 1]), self.q_level ** 2 * n2,
                           self.q_rate ** 2 * n2)
        return out

def ParameterTracker(q: float = 0.01, overlap: float = 1.0) -> TrendTracker:  # noqa: N802
    """A random-walk tracker without trend (the former interface): ``TrendTracker`` with level
    noise ``q`` (relative per sqrt(s)), no rate noise and a rate prior of zero width."""
    return TrendTracker(q_level=q, q_rate=0.0, rate0=1e-12, overlap=overlap)
