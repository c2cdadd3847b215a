"""When will a wearing part cross its limit? Trends with uncertainty and their crossing time.

A :class:`Trend` (level ``v`` at ``t0``, rate ``r``, covariance ``P``) crosses the limit ``L``
at ``tau* = (L - v) / r``; the 90 % interval is where the band ``v + r tau -/+ z s(tau)`` meets
``L``, the roots of ``(r^2 - z^2 P_rr) tau^2 + 2 (a r - z^2 P_vr) tau + (a^2 - z^2 P_vv) = 0``
(``a = v - L``), which exist exactly when the rate is significant at ``z``.
:class:`ForecastEngine` announces, updates and withdraws the predicted crossings.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from estimator.alerts.event import ParameterEvent
from suspid.errors import UsageError

#: two-sided 90 % normal quantile
Z90 = 1.6448536269514722

#: default forecast horizon (s of data time)
DEFAULT_HORIZON_S = 60.0


@dataclass(frozen=True)
class Trend:
    """A level and rate with covariance: the one trend of the monitor and the fleet.

    The abscissa is time (s) or, for a fleet trend against distance, the odometer (m);
    ``rate`` is per unit of it. The extrapolated variance grows by ``q_value tau + q_rate
    tau^3 / 3`` (process noise: the wear may speed up, slow down or stop).
    """

    t: float  # reference abscissa of value
    value: float  # level at t (SI)
    rate: float
    var_value: float  # covariance of (value, rate); NaN when the data cannot give it
    cov: float
    var_rate: float
    q_value: float = 0.0  # SI^2/s
    q_rate: float = 0.0  # SI^2/s^3
    span: float = math.inf  # data time (s) the trend covers
    n: int = 0  # points fitted (0: a tracker's trend)
    outliers: tuple[int, ...] = ()  # indices of points the robust fit gave no weight
    tau: float = 0.0  # scatter beyond the stated stderr (SI; the fleet's random effect)

    @property
    def value_stderr(self) -> float:
        return math.sqrt(max(self.var_value, 0.0)) if math.isfinite(self.var_value) else math.nan

    @property
    def rate_stderr(self) -> float:
        return math.sqrt(max(self.var_rate, 0.0)) if math.isfinite(self.var_rate) else math.nan

    def at(self, x: float) -> float:
        """The line's value at abscissa ``x`` (s, or m) (SI)."""
        return self.value + self.rate * (x - self.t)


@dataclass(frozen=True)
class Crossing:
    """Predicted time at which a trend meets its limit, with the 90 % interval (s)."""

    t: float
    low: float
    high: float


def wls_line(x: np.ndarray, v: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least-squares line ``v = b0 + b1 x`` in closed form (a fleet fits thousands).

    ``w`` are the weights (``1 / variance``). Returns ``(b0, b1)`` and ``M = X' W X`` (the
    unscaled covariance is its inverse); raises :class:`numpy.linalg.LinAlgError` with fewer
    than two weighted points at distinct ``x``.
    """
    wx = w * x
    s0, s1, s2 = float(np.sum(w)), float(np.sum(wx)), float(np.dot(wx, x))
    sy, sxy = float(np.dot(w, v)), float(np.dot(wx, v))
    det = s0 * s2 - s1 * s1
    M = np.array([[s0, s1], [s1, s2]])
    if not det > 0.0:
        raise np.linalg.LinAlgError("singular weighted least-squares line")
    return np.array([(s2 * sy - s1 * sxy) / det, (s0 * sxy - s1 * sy) / det]), M


def inverse_2x2(M: np.ndarray) -> np.ndarray:
    """Inverse of a symmetric positive-definite 2x2 matrix (closed form)."""
    det = float(M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0])
    return np.array([[M[1, 1], -M[0, 1]], [-M[1, 0], M[0, 0]]]) / det


def linear_trend(t: Sequence[float], value: Sequence[float], stderr: Sequence[float],
                 t_ref: float | None = None) -> Trend:
    """Weighted least-squares straight line through ``(t, value +/- stderr)`` (s, SI).

    The covariance is scaled by the reduced chi-square when that exceeds 1; the level refers
    to ``t_ref`` (default the last ``t``).
    """
    tt = np.asarray(t, dtype=float)
    y = np.asarray(value, dtype=float)
    s = np.asarray(stderr, dtype=float)
    ok = np.isfinite(tt) & np.isfinite(y) & np.isfinite(s) & (s > 0)
    tt, y, s = tt[ok], y[ok], s[ok]
    if tt.size < 2 or float(np.ptp(tt)) <= 0:
        raise UsageError(f"a trend needs at least two points at different times, got {tt.size}")
    tr = float(tt[-1]) if t_ref is None else float(t_ref)
    x = tt - tr
    w = 1.0 / (s * s)
    coef, M = wls_line(x, y, w)
    cov = inverse_2x2(M)
    dof = tt.size - 2
    if dof > 0:
        r = y - (coef[0] + coef[1] * x)
        cov = cov * max(1.0, float(np.sum(w * r * r)) / dof)
    return Trend(tr, float(coef[0]), float(coef[1]), float(cov[0, 0]), float(cov[0, 1]),
                 float(cov[1, 1]), n=int(tt.size))


def band_crossing(a: float, r: float, var_value: float, cov: float, var_rate: float,
                  z: float = Z90) -> tuple[float, float, float] | None:
    """Time to a crossing and its interval edges without process noise (Fieller's interval).

    ``a`` is level minus limit, ``r`` the rate, with covariance ``[[var_value, cov], [cov,
    var_rate]]``. Returns ``(tau*, tau_low, tau_high)`` (the unit of ``r``'s time; the edges
    may be negative), ``None`` when the rate is not significant at ``z``.
    """
    qa = r * r - z * z * var_rate
    if r == 0 or not qa > 0:
        return None
    qb = 2.0 * (a * r - z * z * cov)
    qc = a * a - z * z * var_value
    disc = qb * qb - 4.0 * qa * qc
    tc = -a / r
    if disc < 0:   # rounding only: the point estimate always lies inside
        return tc, tc, tc
    root = math.sqrt(disc)
    lo, hi = sorted(((-qb - root) / (2 * qa), (-qb + root) / (2 * qa)))
    return tc, lo, hi


def crossing(trend: Trend, limit: float, z: float = Z90) -> Crossing | None:
    """When ``trend`` reaches ``limit`` (module docstring); ``None`` when not predicted.

    With process noise the band edges are found by bisection, the late one capped at 100
    times the predicted time to the crossing.
    """
    a = trend.value - limit
    r = trend.rate
    if a == 0 or r == 0 or (a > 0) == (r > 0) or r * r <= z * z * trend.var_rate:
        return None
    if trend.q_value == 0.0 and trend.q_rate == 0.0:
        fc = band_crossing(a, r, trend.var_value, trend.cov, trend.var_rate, z)
        if fc is None:
            return None
        tc, lo, hi = fc
        return Crossing(trend.t + tc, trend.t + max(lo, 0.0), trend.t + max(hi, lo, 0.0))
    # work with a > 0 and r < 0 (a falling part above its limit, or the mirror image)
    a, r = abs(a), -abs(r)
    tau = a / -r

    def edge(sign: float) -> float:
        """First tau >= 0 where a + r tau + sign z s(tau) <= 0 (sign -1: early, +1: late)."""
        def g(x: float) -> float:
            var = (trend.var_value + 2.0 * x * trend.cov
                   + x * x * trend.var_rate + trend.q_value * x + trend.q_rate * x ** 3 / 3.0)
            return a + r * x + sign * z * math.sqrt(max(var, 0.0))
        if g(0.0) <= 0:
            return 0.0
        hi = tau
        while g(hi) > 0:
            hi *= 2.0
            if hi > 100.0 * tau:
                return math.inf
        lo = 0.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if g(mid) > 0:
                lo = mid
            else:
                hi = mid
        return hi

    lo = edge(-1.0)
    hi = edge(+1.0)
    if not math.isfinite(hi):
        return None
    return Crossing(trend.t + tau, trend.t + lo, trend.t + max(hi, lo))


@dataclass
class ForecastEvent(ParameterEvent):
    """A predicted limit crossing (``kind="forecast"``) or its withdrawal
    (``"forecast_withdrawn"``): tracked level (SI) and rate (SI/s) at data time ``t`` (s), the
    limit and nominal (SI), and the predicted crossing time with its 90 % interval (s;
    ``None`` in a withdrawal)."""

    kind: str
    t: float
    parameter: str
    value: float
    rate: float
    rate_stderr: float
    limit: float
    nominal: float
    crossing_t: float | None
    crossing_t_low: float | None
    crossing_t_high: float | None
    model: str
    unit: str = ""

    @property
    def message(self) -> str:
        u, pct = self.unit_suffix, self.limit_pct
        if self.kind != "forecast" or self.crossing_t is None:
            return (f"{self.parameter} = {self.value:.6g}{u} no longer trends towards {pct:.0f} % "
                    f"of nominal within the horizon (rate {self.rate:+.3g}{u}/s); "
                    "forecast withdrawn")
        lo = self.crossing_t_low if self.crossing_t_low is not None else self.crossing_t
        hi = self.crossing_t_high if self.crossing_t_high is not None else self.crossing_t
        return (f"{self.parameter} = {self.value:.6g}{u} falling at {self.rate:.3g}{u}/s will "
                f"cross {pct:.0f} % of nominal ({self.limit:.6g}{u}) at t = {self.crossing_t:.1f} s "
                f"(90 % interval {lo:.1f}-{hi:.1f} s, in {self.crossing_t - self.t:.1f} s); "
                "plan the replacement")

    def to_json(self) -> dict[str, Any]:
        """The ``forecast`` (or ``forecast_withdrawn``) JSON line."""
        return {"type": self.kind, "t": self.t, "parameter": self.parameter,
                "value": self.value, "rate": self.rate, "rate_stderr": self.rate_stderr,
                "limit": self.limit, "nominal": self.nominal, "crossing_t": self.crossing_t,
                "crossing_t_low": self.crossing_t_low, "crossing_t_high": self.crossing_t_high,
                "message": self.message, "model": self.model, "id": self.id}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> "ForecastEvent":
        def opt(k: str) -> float | None:
            v = d.get(k)
            return None if v is None else float(v)

        return cls(kind=str(d["type"]), t=float(d["t"]), parameter=str(d["parameter"]),
                   value=float(d["value"]), rate=float(d["rate"]),
                   rate_stderr=float(d.get("rate_stderr") or 0.0), limit=float(d["limit"]),
                   nominal=float(d.get("nominal") or 0.0), crossing_t=opt("crossing_t"),
                   crossing_t_low=opt("crossing_t_low"), crossing_t_high=opt("crossing_t_high"),
                   model=str(d.get("model", "")))


@dataclass
class ForecastEngine:
    """Per-parameter forecast state: announce, update and withdraw predicted crossings.

    ``publish`` receives each new event and returns whether it was delivered (the alert
    engine's write-ahead publisher); by default the events are only collected.
    """

    limits: dict[str, float]  # parameter -> limit (SI)
    nominal: dict[str, float]
    horizon_s: float = DEFAULT_HORIZON_S  # announce crossings predicted within this (s)
    model: str = ""
    units: dict[str, str] = field(default_factory=dict)
    publish: Any = None
    min_span_s: float = 15.0  # announce nothing from a trend spanning less data time (s)
    active: dict[str, ForecastEvent] = field(default_factory=dict)
    emitted: list[ForecastEvent] = field(default_factory=list)

    def update(self, trends: Mapping[str, Trend]) -> list[ForecastEvent]:
        """Fold in the tracker's trends at one estimate; returns the events emitted now."""
        out: list[ForecastEvent] = []
        for k, tr in trends.items():
            if k not in self.limits:
                continue
            if tr.value <= self.limits[k]:
                # crossed: the alert engine takes over; the forecast is fulfilled, not withdrawn
                self.active.pop(k, None)
                continue
            cr = crossing(tr, self.limits[k])
            prev = self.active.get(k)
            if prev is not None and (cr is None or not cr.t - tr.t <= 1.5 * self.horizon_s):
                del self.active[k]
                self._publish(self._event("forecast_withdrawn", tr, k, None), out)
                continue
            if cr is None:
                continue
            if prev is None:   # announced within the horizon, from a long enough trend
                new = (cr.t - tr.t <= self.horizon_s and cr.high - tr.t <= 2.0 * self.horizon_s
                       and tr.span >= self.min_span_s)
            else:   # replaced when the crossing left the interval announced
                new = (prev.crossing_t_low is not None and prev.crossing_t_high is not None
                       and not prev.crossing_t_low <= cr.t <= prev.crossing_t_high)
            if new:
                ev = self._event("forecast", tr, k, cr)
                self.active[k] = ev
                self._publish(ev, out)
        return out

    def _event(self, kind: str, tr: Trend, k: str, cr: Crossing | None) -> ForecastEvent:
        return ForecastEvent(kind, float(tr.t), k, float(tr.value), float(tr.rate),
                             float(tr.rate_stderr), float(self.limits[k]),
                             float(self.nominal.get(k, 0.0)),
                             None if cr is None else float(cr.t),
                             None if cr is None else float(cr.low),
                             None if cr is None else float(cr.high),
                             self.model, self.units.get(k, ""))

    def _publish(self, ev: ForecastEvent, out: list[ForecastEvent]) -> None:
        if self.publish is None or self.publish(ev):
            self.emitted.append(ev)
            out.append(ev)
