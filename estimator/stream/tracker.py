"""Parameter tracking with a trend: a two-model local-linear-trend filter over window estimates.

Each parameter's state is ``[value, rate]`` (SI, SI/s) with level and rate random walks scaled
by its nominal value; a *steady* and a *changing* rate model run as an interacting-multiple-
model filter. A window estimate, describing the window's middle, is folded in as ``y = v(t) -
lag r(t)`` so the track refers to the window's end. The stated variances are calibrated to
the estimates' scatter and widened where the innovations show the track lagging; a rate that
changes is restarted an estimate back when a likelihood-ratio test prefers it. Rules and
measurements: ``docs/monitoring.md``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from estimator.alerts.forecast import Trend


_Snap = tuple[float, list[np.ndarray], list[np.ndarray], np.ndarray]   # t, xs, Ps, mu


@dataclass
class _Track:
    x: np.ndarray       # [value, rate] (SI, SI/s): the mixture
    P: np.ndarray       # 2x2 covariance of the mixture
    t: float
    nominal: float
    t0: float = math.nan    # data time the first estimate describes
    xs: list[np.ndarray] = field(default_factory=list)   # per model
    Ps: list[np.ndarray] = field(default_factory=list)
    mu: np.ndarray = field(default_factory=lambda: np.ones(1))
    recent: list[tuple[float, float]] = field(default_factory=list)  # (value, stderr), last 3
    calib: tuple[float, float] = (0.0, 0.0)   # weighted sum of d^2/var, weighted count
    # the last estimates: the filter before each, its time, value, variance, log-likelihood
    hist: list[tuple[_Snap, float, float, float, float]] = field(default_factory=list)
    innov: tuple[float, float] = (0.0, 0.0)   # weighted sum of nu^2 / S, weighted count
    held: int = 0     # consecutive estimates with the changing model at restart_mu or above
    hold: int = 0     # estimates to go before a restarted rate may be forecast from


@dataclass
class TrendTracker:
    """Per-parameter two-model local-linear-trend filter (see the module docstring).

    Noise levels are relative to the nominal value: ``q_level`` per sqrt(s), the rate walks
    per s per sqrt(s), ``rate0`` and ``restart_rate`` per s.
    """

    q_level: float = 5e-4  # level random walk
    q_rate: float = 5e-5  # rate random walk of the steady model
    q_rate_change: float = 1e-3  # of the changing model (<= q_rate: a single filter)
    p_switch: float = 0.01  # probability of a model switch between two estimates
    rate0: float = 0.01  # prior standard deviation of the rate
    lag: float = 0.0  # data time (s) from a window's end back to the time its estimate describes
    lags: dict[str, float] = field(default_factory=dict)  # per parameter (drift-fitted: 0)
    overlap: float = 1.0  # measurement-variance inflation of overlapping windows (window / step)
    calibrate: bool = True  # scale the stated variances by the estimates' scatter (lambda)
    calib_prior: float = 2.0  # pseudo-observations of lambda = 1
    calib_memory: float = 50.0  # memory (estimates) of lambda's weighted mean
    calib_min: float = 0.05
    calib_max: float = 20.0
    forecast_settle_s: float = 20.0  # extra rate variance of the trends right after a kink
    forecast_settle_power: float = 8.0
    restart_mu: float = 0.5  # changing-model probability that restarts the rate
    restart_rate: float = 0.005  # width of the restarted rate's prior; 0: no restart
    restart_glr: float = 3.84  # 2 Delta log L a restart must pass
    restart_hold: int = 2  # estimates during which the trend reports no data span
    innov_scale: bool = True  # widen the reported variances by the innovations' kappa^2
    innov_prior: float = 0.5  # pseudo-observations of kappa^2 = 1
    innov_memory: float = 2.0  # memory (estimates) of the mean of nu^2 / S
    innov_max: float = 25.0  # upper clip of kappa^2 (the lower is 1)
    innov_rate: float = 0.25  # exponent of kappa^2 on the rate's variance
    nominal: dict[str, float] = field(default_factory=dict)  # noise scale (else the first estimate)
    tracks: dict[str, _Track] = field(default_factory=dict)

    @property
    def _qs(self) -> tuple[float, ...]:
        if self.q_rate_change > self.q_rate:
            return (self.q_rate, self.q_rate_change)
        return (self.q_rate,)

    def _Q(self, dt: float, nominal: float, q: float) -> np.ndarray:  # noqa: N802
        n2 = nominal * nominal
        Q = q * q * n2 * np.array([[dt ** 3 / 3.0, dt * dt / 2.0], [dt * dt / 2.0, dt]])
        Q[0, 0] += self.q_level ** 2 * n2 * dt
        return Q

    def _mix(self, tr: _Track) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray]:
        """IMM interaction: the models' starting states and the predicted probabilities."""
        m = len(tr.xs)
        if m == 1:
            return [tr.xs[0]], [tr.Ps[0]], tr.mu
        p = self.p_switch
        Pi = np.full((m, m), p / (m - 1))
        np.fill_diagonal(Pi, 1.0 - p)
        c = Pi.T @ tr.mu
        W = (Pi * tr.mu[:, None]) / c[None, :]      # W[i, j]: P(model i before | j after)
        x0, P0 = [], []
        for j in range(m):
            xj = sum(W[i, j] * tr.xs[i] for i in range(m))
            Pj = sum(W[i, j] * (tr.Ps[i] + np.outer(tr.xs[i] - xj, tr.xs[i] - xj))
                     for i in range(m))
            x0.append(np.asarray(xj))
            P0.append(np.asarray(Pj))
        return x0, P0, c

    def _combine(self, tr: _Track) -> None:
        x = sum(w * xi for w, xi in zip(tr.mu, tr.xs))
        P = sum(w * (Pi + np.outer(xi - x, xi - x)) for w, xi, Pi in zip(tr.mu, tr.xs, tr.Ps))
        tr.x = np.asarray(x, dtype=float)
        tr.P = np.asarray(P, dtype=float)

    def _predict(self, tr: _Track, t: float) -> None:
        dt = max(t - tr.t, 0.0)
        if dt == 0.0:
            return
        F = np.array([[1.0, dt], [0.0, 1.0]])
        x0, P0, c = self._mix(tr)
        tr.xs = [F @ x for x in x0]
        tr.Ps = [F @ P @ F.T + self._Q(dt, tr.nominal, q) for P, q in zip(P0, self._qs)]
        tr.mu = c
        tr.t = t
        self._combine(tr)

    def scale(self, name: str) -> float:
        """The calibrated variance scale ``lambda`` of a parameter (1 without calibration)."""
        tr = self.tracks.get(name)
        return 1.0 if tr is None else self.scale_of(tr)

    def honesty(self, name: str) -> float:
        """The factor ``kappa^2`` on a parameter's tracked variances (1 without it)."""
        tr = self.tracks.get(name)
        if tr is None or not (self.calibrate and self.innov_scale):
            return 1.0
        num, den = tr.innov
        k2 = (self.innov_prior + num) / (self.innov_prior + den)
        return min(self.innov_max, max(1.0, k2))

    def _innovate(self, tr: _Track, t: float, v: float, se: float, lag: float) -> None:
        """Fold the normalized innovation ``nu^2 / S`` of estimate ``v`` (SI) at ``t`` (s)."""
        if not (self.calibrate and self.innov_scale):
            return
        self._predict(tr, t)
        H = np.array([1.0, -lag])
        S = float(H @ tr.P @ H) + se * se * self.overlap * self.scale_of(tr)
        nu = v - float(H @ tr.x)
        f = 1.0 - 1.0 / self.innov_memory
        num, den = tr.innov
        tr.innov = (f * num + nu * nu / S, f * den + 1.0)

    def scale_of(self, tr: _Track) -> float:
        """``lambda`` of a track (see :meth:`scale`)."""
        if not self.calibrate:
            return 1.0
        num, den = tr.calib
        lam = (self.calib_prior + num) / (self.calib_prior + den)
        return min(self.calib_max, max(self.calib_min, lam))

    def _calibrate(self, tr: _Track, v: float, se: float) -> None:
        tr.recent.append((v, se))
        del tr.recent[:-3]
        if not self.calibrate or len(tr.recent) < 3:
            return
        (y0, s0), (y1, s1), (y2, s2) = tr.recent
        d = y2 - 2.0 * y1 + y0
        z = d * d / (s0 * s0 + 4.0 * s1 * s1 + s2 * s2)
        f = 1.0 - 1.0 / self.calib_memory
        num, den = tr.calib
        tr.calib = (f * num + z, f * den + 1.0)

    def update(self, t: float, values: Mapping[str, float], stderr: Mapping[str, float]
               ) -> dict[str, dict[str, float]]:
        """Fold in one window estimate ending at ``t`` (s); returns ``parameter -> {"value",
        "stderr", "rate", "rate_stderr"}`` (SI, SI/s) at ``t``."""
        for k, se in stderr.items():
            v = values.get(k)
            if v is None or not (math.isfinite(v) and math.isfinite(se) and se > 0):
                continue
            tr = self.tracks.get(k)
            lag = self.lags.get(k, self.lag)
            if tr is None:
                nom = self.nominal.get(k) or abs(v) or 1.0
                P = np.diag([se * se * self.overlap, (self.rate0 * nom) ** 2])
                # the first estimate describes t - lag: move the level to t with the prior rate
                P[0, 0] += (lag * self.rate0 * nom) ** 2
                x = np.array([float(v), 0.0])
                m = len(self._qs)
                mu = np.ones(1) if m == 1 else np.array([1.0 - self.p_switch, self.p_switch])
                tr = self.tracks[k] = _Track(x.copy(), P.copy(), t, nom, t - 2.0 * lag,
                                             [x.copy() for _ in range(m)],
                                             [P.copy() for _ in range(m)], mu)
                self._calibrate(tr, float(v), float(se))
                continue
            before = self._snapshot(tr)
            self._innovate(tr, t, float(v), float(se), lag)
            self._calibrate(tr, float(v), float(se))
            r = se * se * self.overlap * self.scale_of(tr)
            ll = self._step(tr, t, float(v), r, lag)
            tr.hist.append((before, t, float(v), r, ll))
            tr.held = tr.held + 1 if float(tr.mu[-1]) >= self.restart_mu else 0
            tr.hold = max(tr.hold - 1, 0)
            # the restart goes back one estimate, as soon as the changing model takes over
            if (tr.mu.size > 1 and self.restart_rate > 0.0 and (lag > 0.0 or k in self.lags)
                    and len(tr.hist) > 1 and tr.held == 1):
                self._restart(tr, lag)
            del tr.hist[:-2]
        return self.state(t)

    def _step(self, tr: _Track, t: float, v: float, r: float, lag: float) -> float:
        """Predict to ``t`` and fold in one estimate ``v`` of variance ``r`` (both models)."""
        self._predict(tr, t)
        H = np.array([1.0, -lag])
        like = np.empty(len(tr.xs))
        for j, (x, P) in enumerate(zip(tr.xs, tr.Ps)):
            S = float(H @ P @ H) + r
            K = (P @ H) / S
            nu = v - float(H @ x)
            tr.xs[j] = x + K * nu
            Pn = P - np.outer(K, H @ P)
            tr.Ps[j] = 0.5 * (Pn + Pn.T)
            like[j] = math.exp(-0.5 * nu * nu / S) / math.sqrt(S)
        mu = tr.mu * like
        total = float(mu.sum())
        tr.mu = mu / total if total > 0 and math.isfinite(total) else tr.mu
        self._combine(tr)
        return math.log(total) if total > 0 and math.isfinite(total) else -math.inf

    @staticmethod
    def _snapshot(tr: _Track) -> _Snap:
        return tr.t, [x.copy() for x in tr.xs], [P.copy() for P in tr.Ps], tr.mu.copy()

    def _restore(self, tr: _Track, snap: _Snap) -> None:
        t0, xs, Ps, mu = snap
        tr.t, tr.xs, tr.Ps, tr.mu = t0, [x.copy() for x in xs], [P.copy() for P in Ps], mu.copy()
        self._combine(tr)

    def _restart(self, tr: _Track, lag: float) -> None:
        """The changing model has just taken over: go back one estimate, widen the rate
        by ``restart_rate`` and fold them in again; kept only if ``2 (log L_restart - log L)
        >= restart_glr``, then no forecast span for ``restart_hold`` estimates."""
        old = tr.hist[-2:]
        keep = self._snapshot(tr)
        self._restore(tr, old[0][0])
        extra = (self.restart_rate * tr.nominal) ** 2
        tr.Ps = [P + np.array([[0.0, 0.0], [0.0, extra]]) for P in tr.Ps]
        new = []
        for _, t, v, r, _ in old:
            snap = self._snapshot(tr)
            new.append((snap, t, v, r, self._step(tr, t, v, r, lag)))
        if 2.0 * sum(n[4] - o[4] for n, o in zip(new, old)) < self.restart_glr:
            self._restore(tr, keep)
            return
        tr.hist[-len(new):] = new
        tr.hold = self.restart_hold

    def state(self, t: float | None = None) -> dict[str, dict[str, float]]:
        """The tracked values at ``t`` (default: each track's last update), JSON-ready."""
        return {k: {"value": tr.value, "stderr": tr.value_stderr, "rate": tr.rate,
                    "rate_stderr": tr.rate_stderr} for k, tr in self.trends(t).items()}

    def trends(self, t: float | None = None) -> dict[str, Trend]:
        """Each track as a :class:`~estimator.alerts.forecast.Trend` at ``t``."""
        out: dict[str, Trend] = {}
        for k, tr in self.tracks.items():
            if t is not None and t > tr.t:
                self._predict(tr, t)
            n2 = tr.nominal * tr.nominal
            # the extrapolation keeps the level's random walk, not the rate's; right after a
            # kink the rate variance gets ``forecast_settle_s`` more of the changing model's
            extra = (float(tr.mu[1]) ** self.forecast_settle_power * self.q_rate_change ** 2
                     * n2 * self.forecast_settle_s if tr.mu.size > 1 else 0.0)
            h = self.honesty(k)
            hr = h ** self.innov_rate
            out[k] = Trend(tr.t, float(tr.x[0]), float(tr.x[1]), h * float(tr.P[0, 0]),
                           math.sqrt(h * hr) * float(tr.P[0, 1]), hr * float(tr.P[1, 1]) + extra,
                           self.q_level ** 2 * n2, 0.0, 0.0 if tr.hold else tr.t - tr.t0)
        return out

