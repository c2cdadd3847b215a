"""Per-vehicle trends of identified parameters across drives, and limit-crossing forecasts.

A robust random-effects line (Huber and bisquare IRLS, Paule–Mandel ``tau^2``) and Fieller's
interval of its limit crossing, described in ``docs/fleet.md``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import t as student_t

from estimator.alerts.forecast import Trend, band_crossing, inverse_2x2, wls_line

DAY_S = 86400.0
#: m per km: the abscissa unit of a trend against distance
KM = 1000.0
#: a forecast's keys of the crossing against distance (odometer km, 90 % interval)
KM_KEYS = ("crossing_km", "crossing_km_low", "crossing_km_high")
HUBER_C = 1.345
BISQUARE_C = 4.685
MAD_TO_SIGMA = 1.4826


@dataclass
class Forecast:
    """When a falling trend crosses its limit (epoch s, 90 % interval), never before ``t_latest``;
    ``crossing_m`` the odometer (m) at the crossing from the trend against distance.
    """

    crossing_t: float
    crossing_t_low: float
    crossing_t_high: float
    limit: float
    level: float = 0.90
    t_latest: float = math.nan
    distance: bool = False
    crossing_m: tuple[float, float, float] | None = None

    def days(self) -> tuple[float, float, float]:
        """The crossing and its interval in days after the latest drive."""
        return ((self.crossing_t - self.t_latest) / DAY_S,
                (self.crossing_t_low - self.t_latest) / DAY_S,
                (self.crossing_t_high - self.t_latest) / DAY_S)

    def to_json(self) -> dict[str, float | None]:
        """``crossing_t*`` (epoch s), ``limit``, ``days*`` after the latest drive, ``crossing_km*``."""
        out: dict[str, float | None] = {
            "crossing_t": self.crossing_t, "crossing_t_low": self.crossing_t_low,
            "crossing_t_high": self.crossing_t_high, "limit": self.limit}
        for k, d in zip(("days", "days_low", "days_high"), self.days()):
            out[k] = round(d, 3) if math.isfinite(d) else None
        if self.distance:
            for i, k in enumerate(KM_KEYS):
                out[k] = None if self.crossing_m is None else round(self.crossing_m[i] / 1e3, 3)
        return out


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _median(a: np.ndarray) -> float:
    """The median of a small 1-D array (``np.median`` without its overhead)."""
    b = np.sort(a)
    n = b.size
    return float(b[n // 2]) if n % 2 else 0.5 * float(b[n // 2 - 1] + b[n // 2])


def robust_trend(t: np.ndarray, v: np.ndarray, s: np.ndarray | None = None, scale: float = DAY_S
                 ) -> Trend | None:
    """Robust weighted straight-line trend of ``v`` (SI, stderr ``s``; NaN: unknown) over ``t``.

    ``t`` is epoch s, or odometer m for a trend against distance; ``scale`` the abscissa's unit in
    the fit (s per day, or 1000 m). Returns the :class:`Trend` (per s or m) at the latest abscissa,
    ``None`` with fewer than two distinct abscissae (NaN covariance with two).
    """
    t = np.asarray(t, dtype=float)
    v = np.asarray(v, dtype=float)
    s = np.full_like(v, np.nan) if s is None else np.asarray(s, dtype=float)
    idx = np.flatnonzero(np.isfinite(t) & np.isfinite(v))
    if idx.size < 2:
        return None
    t, v, s = t[idx], v[idx], s[idx]
    s = np.where(np.isfinite(s) & (s >= 0), s, 0.0)
    t_ref = float(t.max())
    x = (t - t_ref) / scale
    if np.ptp(x) == 0:
        return None
    n = x.size
    # the Theil--Sen line: median pairwise slope (pairs with distinct x)
    i, j = np.triu_indices(n, 1)
    dx = x[j] - x[i]
    ok = dx != 0
    b = float(np.median((v[j] - v[i])[ok] / dx[ok])) if ok.any() else 0.0
    a = float(np.median(v - b * x))
    if n == 2:
        return Trend(t_ref, a, b / scale, math.nan, math.nan, math.nan, n=n)
    floor = (1e-12 * max(float(np.max(np.abs(v))), 1e-300)) ** 2
    beta = np.array([a, b])
    h = np.ones(n)
    tau2 = 0.0
    var = s * s
    M = np.eye(2)
    for c, kind in ((HUBER_C, "huber"), (BISQUARE_C, "bisquare")):
        for _ in range(50):
            r = v - (beta[0] + beta[1] * x)
            mad = MAD_TO_SIGMA * _median(np.abs(r - _median(r)))
            tau2 = max(0.0, mad * mad - _median(s * s))
            var = np.maximum(s * s + tau2, floor)
            u = np.abs(r) / np.sqrt(var)
            if kind == "huber":
                h = np.minimum(1.0, c / np.maximum(u, 1e-300))
            else:
                h = np.where(u < c, (1.0 - (u / c) ** 2) ** 2, 0.0)
            w = h / var
            if np.count_nonzero(w) < 2 or np.ptp(x[w > 0]) == 0:
                break
            new, M = wls_line(x, v, w)
            done = (abs(new[0] - beta[0]) <= 1e-12 * abs(beta[0])
                    and abs(new[1] - beta[1]) <= 1e-12 * abs(beta[1]))
            beta = new
            if done:
                break
    keep = h > 0
    if np.count_nonzero(keep) < 3 or np.ptp(x[keep]) == 0:
        keep = np.ones(n, dtype=bool)
    beta, M, tau2 = _random_effects(x[keep], v[keep], s[keep], floor)
    # a rejected drive within the bisquare cut of the final fit's own scale is readmitted
    for _ in range(3):
        u = np.abs(v - (beta[0] + beta[1] * x)) / np.sqrt(np.maximum(s * s + tau2, floor))
        again = keep | (u < BISQUARE_C)
        if np.array_equal(again, keep):
            break
        keep = again
        beta, M, tau2 = _random_effects(x[keep], v[keep], s[keep], floor)
    r = v[keep] - (beta[0] + beta[1] * x[keep])
    w = 1.0 / np.maximum(s[keep] ** 2 + tau2, floor)
    phi = max(1.0, float(np.sum(w * r * r)) / max(np.count_nonzero(keep) - 2.0, 1.0))
    cov = phi * inverse_2x2(M)
    outliers = tuple(int(idx[i]) for i in np.flatnonzero(~keep))
    return Trend(t_ref, float(beta[0]), float(beta[1]) / scale, float(cov[0, 0]),
                 float(cov[0, 1]) / scale, float(cov[1, 1]) / (scale * scale),
                 n=int(np.count_nonzero(keep)), outliers=outliers, tau=math.sqrt(tau2))


def trend_json(trend: Trend, per: float = DAY_S, unit: str = "day") -> dict[str, object]:
    """A fleet trend as JSON (``rate_per_<unit>``, ``stderr``, ``value``, ``drives``, ``outliers``)."""
    return {f"rate_per_{unit}": _num(trend.rate * per), "stderr": _num(trend.rate_stderr * per),
            "value": _num(trend.value), "drives": int(trend.n), "outliers": len(trend.outliers)}


def _random_effects(x: np.ndarray, v: np.ndarray, s: np.ndarray, floor: float
                    ) -> tuple[np.ndarray, np.ndarray, float]:
    """WLS line with weights ``1 / (s^2 + tau^2)``, ``tau^2 >= 0`` by Paule–Mandel (RSS = ``n - 2``)."""
    dof = max(x.size - 2.0, 1.0)

    def at(tau2: float) -> tuple[np.ndarray, np.ndarray, float]:
        w = 1.0 / np.maximum(s * s + tau2, floor)
        beta, M = wls_line(x, v, w)
        r = v - (beta[0] + beta[1] * x)
        return beta, M, float(np.sum(w * r * r))

    beta, M, q = at(0.0)
    if q <= dof:
        return beta, M, 0.0
    lo, hi = 0.0, max(float(np.var(v)) * 4.0, float(np.max(s * s)), floor)
    while at(hi)[2] > dof and hi < 1e300:
        hi *= 4.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if at(mid)[2] > dof:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-12 * hi:
            break
    beta, M, _ = at(hi)
    return beta, M, hi


def limit_crossing(trend: Trend | None, limit: float, level: float = 0.90,
                   not_before: float | None = None) -> tuple[float, float, float] | None:
    """Where a falling trend crosses ``limit``: ``(crossing, low, high)`` with Fieller's ``level``
    interval, never before ``not_before``; ``None`` when its slope is not clearly below zero.
    """
    if trend is None or not (trend.n >= 3 and math.isfinite(trend.var_rate)):
        return None
    a, b = trend.value - limit, trend.rate
    if not b < 0:
        return None
    q = float(student_t.ppf(0.5 + level / 2.0, max(trend.n - 2, 1)))
    fc = band_crossing(a, b, trend.var_value, trend.cov, trend.var_rate, q)
    if fc is None:
        return None
    tc, lo, hi = fc
    x0 = trend.t if not_before is None else max(float(not_before), trend.t)
    return max(trend.t + tc, x0), max(trend.t + lo, x0), max(trend.t + hi, x0)


def forecast_crossing(trend: Trend | None, limit: float, level: float = 0.90,
                      not_before: float | None = None) -> Forecast | None:
    """Date a falling trend over time crosses ``limit`` (:func:`limit_crossing`; ``None`` as it)."""
    fc = limit_crossing(trend, limit, level, not_before)
    if trend is None or fc is None:
        return None
    t0 = trend.t if not_before is None else max(float(not_before), trend.t)
    return Forecast(fc[0], fc[1], fc[2], float(limit), level, t0)
