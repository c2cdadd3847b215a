"""Residual analysis: output-residual statistics and the residual *force* against candidate effects.

The residual force ``R = M q'' + C q' + K q - Fk r - Fc r'`` is regressed on the parameter
sensitivities plus each candidate's regressors (its parameters, refined base parameters and
the share of ``R`` it explains); sensor effects are screened in the output residual.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import savgol_coeffs, savgol_filter
from scipy.stats import chi2

from suspid.errors import UsageError
from suspid.io.csvio import Measurement
from suspid.models.base import FloatArray, SuspensionModel
from suspid.effects import PhysicalEffect, SensorEffect, Site, Trial, effect_classes

# ------------------------------------------------------------------------- statistics


def autocorr(e: FloatArray, maxlag: int) -> FloatArray:
    """Sample autocorrelation of ``e`` (NaNs dropped) at lags ``0..maxlag``."""
    x = np.asarray(e, dtype=float)
    x = x[~np.isnan(x)]
    x = x - x.mean()
    d = float(x @ x)
    n = x.size
    if d <= 0 or n < 3:
        return np.zeros(maxlag + 1)
    return np.array([float(x[: n - k] @ x[k:]) / d for k in range(min(maxlag, n - 1) + 1)])


def noise_variance(e: FloatArray) -> float:
    """White-noise variance estimate ``var(second difference) / 6`` (smooth parts cancel)."""
    x = np.asarray(e, dtype=float)
    d2 = np.diff(x, 2)
    d2 = d2[~np.isnan(d2)]
    return float(np.mean(d2 ** 2) / 6.0) if d2.size else 0.0


def xcorr_peak(a: FloatArray, b: FloatArray, maxlag: int) -> tuple[float, int]:
    """Largest normalised cross-correlation ``(rho, lag)``, ``|lag| <= maxlag`` (> 0: ``a`` follows)."""
    ok = ~(np.isnan(a) | np.isnan(b))
    if not ok.any():
        return 0.0, 0
    x = a[ok] - np.mean(a[ok])
    y = b[ok] - np.mean(b[ok])
    den = math.sqrt(float(x @ x) * float(y @ y))
    if den <= 0:
        return 0.0, 0
    n = x.size
    maxlag = min(maxlag, n - 1)
    best, lag = 0.0, 0
    for k in range(-maxlag, maxlag + 1):
        v = float(x[k:] @ y[: n - k]) if k >= 0 else float(x[: n + k] @ y[-k:])
        if abs(v) > abs(best):
            best, lag = v, k
    return best / den, lag


def effective_n(e: FloatArray) -> float:
    """Effective number of independent samples under an AR(1) approximation."""
    x = np.asarray(e, dtype=float)
    n = int(np.sum(~np.isnan(x)))
    rho = float(np.clip(autocorr(x, 1)[1], -0.99, 0.99))
    return max(2.0, n * (1 - rho) / (1 + rho))


@dataclass
class ChannelStats:
    """Residual statistics of one channel (SI units of the channel)."""

    channel: str
    rms: float
    signal_rms: float
    noise_rms: float
    structured_rms: float
    ljung_box_q: float
    ljung_box_p: float
    acf_lag1: float
    mean: float = 0.0
    mean_p: float = 1.0

    @property
    def white_p(self) -> float:
        """Smallest p-value of the whiteness tests (Ljung–Box, zero mean)."""
        return min(self.ljung_box_p, self.mean_p)

    def to_json(self) -> dict[str, float | str]:
        return {k: v for k, v in asdict(self).items() if k != "channel"}


def channel_stats(name: str, e: FloatArray, y: FloatArray, lags: int = 20, skip: int = 0) -> ChannelStats:
    """Residual ``e`` of signal ``y``; whiteness ignores the first ``skip`` samples."""
    rms = float(np.sqrt(np.nanmean(e ** 2)))
    nv = noise_variance(e)
    # the Ljung–Box statistic and its chi-square p-value (no lag to test below 3 samples)
    n = int(np.sum(~np.isnan(e[skip:])))
    q, p = 0.0, 1.0
    if n >= 3:
        rho = autocorr(e[skip:], max(1, min(lags, n // 4)))[1:]
        q = float(n * (n + 2) * np.sum(rho ** 2 / (n - np.arange(1, rho.size + 1))))
        p = float(chi2.sf(q, rho.size))
    m, mp = mean_test(e[skip:])
    return ChannelStats(name, rms, float(np.sqrt(np.nanmean(y ** 2))), math.sqrt(nv),
                        math.sqrt(max(rms ** 2 - nv, 0.0)), q, p, float(autocorr(e[skip:], 1)[1]),
                        m, mp)


def mean_test(e: FloatArray) -> tuple[float, float]:
    """Mean of ``e`` and the p-value of ``mean = 0`` (Ljung–Box cannot see a constant offset)."""
    x = np.asarray(e, dtype=float)
    x = x[~np.isnan(x)]
    if x.size < 3:
        return 0.0, 1.0
    m = float(np.mean(x))
    sd = float(np.std(x))
    if sd <= 0:
        return m, (1.0 if m == 0 else 0.0)
    z = abs(m) / (sd / math.sqrt(effective_n(x)))
    return m, float(math.erfc(z / math.sqrt(2.0)))


# ------------------------------------------------------------------------- signals
def shift_allpass(t: FloatArray, y: FloatArray, dt: float) -> FloatArray:
    """``y(t + dt)`` by an all-pass (Fourier) fractional shift (s, channel units).

    Interpolation would low-pass the noise and reward any sub-sample shift. The first value is held
    before the start, NaN beyond the end; non-uniform sampling falls back to a cubic spline.
    """
    tt = np.asarray(t, dtype=float)
    yy = np.asarray(y, dtype=float)
    n = tt.size
    ok = ~np.isnan(yy)
    if n < 4 or ok.sum() < 4:
        return np.interp(tt + dt, tt[ok], yy[ok], right=np.nan) if ok.any() else yy.copy()
    steps = np.diff(tt)
    h = float(np.median(steps))
    tq = tt + dt
    if h <= 0 or np.max(np.abs(steps - h)) > 1e-3 * h:
        out = CubicSpline(tt[ok], yy[ok], extrapolate=False)(tq)
    else:
        yf = yy if ok.all() else np.interp(tt, tt[ok], yy[ok])
        tau, T = tt - tt[0], tt[-1] - tt[0]
        m = min(n, 5)
        a0 = np.polyfit(tau[:m], yf[:m], 2)
        a1 = np.polyfit(tau[-m:] - T, yf[-m:], 2)
        s0, s1 = float(a0[1]), float(a1[1])   # slopes at the two ends (local quadratics)

        def trend(x: FloatArray) -> FloatArray:
            return s0 * x + (s1 - s0) * x * x / (2.0 * T)

        ext = yf - trend(tau)
        ext = np.concatenate([ext, ext[::-1]])
        w = 2.0 * math.pi * np.fft.rfftfreq(2 * n, h)
        out = np.fft.irfft(np.fft.rfft(ext) * np.exp(1j * w * dt), 2 * n)[:n] + trend(tau + dt)
        if not ok.all():
            lost = np.interp(tq, tt, (~ok).astype(float)) > 0
            out = np.where(lost, np.nan, out)
    first = int(np.argmax(ok))
    out = np.where(tq < tt[first], yy[first], out)
    last = n - 1 - int(np.argmax(ok[::-1]))
    return np.where(tq > tt[last] + 1e-9 * h, np.nan, out)


def _savgol_window(n: int, fs: float, seconds: float = 0.02) -> int:
    """Odd Savitzky–Golay window of about ``seconds`` (at least 7, at most the record)."""
    w = max(int(round(seconds * fs)) | 1, 7)
    top = n if n % 2 else n - 1
    return min(w, top)


@dataclass
class Motion:
    """Smoothed motion used for the residual force: ``q``, ``q'``, ``q''`` (N, nq), roads (N, nr)."""

    q: FloatArray
    qd: FloatArray
    qdd: FloatArray
    r: FloatArray
    rd: FloatArray
    source: dict[str, str]  # channel -> "measured" | "derived" | "model"


def motion_from(model: SuspensionModel, meas: Measurement, predicted: Mapping[str, FloatArray],
                U: FloatArray) -> Motion:
    """Coordinates and derivatives from the measurement (Savitzky–Golay smoothed), gaps from ``predicted``."""
    t = meas.t
    n = t.size
    fs = (n - 1) / (t[-1] - t[0])
    w = _savgol_window(n, fs)
    h = 1.0 / fs
    nq = len(model.coords)
    src: dict[str, str] = {}

    def get(ch: str) -> FloatArray | None:
        y = meas.measured.get(ch)
        if y is None:
            return None
        y = np.asarray(y, dtype=float)
        if np.isnan(y).any():
            ok = ~np.isnan(y)
            if ok.sum() < n // 2:
                return None
            y = np.interp(t, t[ok], y[ok])
        return y

    def smooth(y: FloatArray, deriv: int = 0) -> FloatArray:
        return savgol_filter(y, w, 3, deriv=deriv, delta=h)

    suffixes = ("", "_dot", "_ddot")
    Q, QD, QDD = derivs = [np.empty((n, nq)) for _ in suffixes]
    for i, c in enumerate(model.coords):
        ys = [get(c + sfx) for sfx in suffixes]
        for k, sfx in enumerate(suffixes):
            # the highest measured order up to k, differentiated to k; else the model's
            j, y = next(((j, y) for j in range(k, -1, -1) if (y := ys[j]) is not None),
                        (k, None))
            if y is None:
                derivs[k][:, i] = smooth(predicted[c + sfx])
                src[c + sfx] = "model"
            else:
                derivs[k][:, i] = smooth(y, k - j)
                src[c + sfx] = "measured" if j == k else "derived"
    nr = len(model.roads)
    r = np.column_stack([smooth(U[:, j]) for j in range(nr)])
    rd = np.column_stack([smooth(U[:, nr + j]) for j in range(nr)])
    return Motion(Q, QD, QDD, r, rd, src)


def residual_force(model: SuspensionModel, p: Mapping[str, float], mo: Motion) -> FloatArray:
    """Residual generalised force ``R = M q'' + C q' + K q - Fk r - Fc r'`` (N, nq) (N, N m)."""
    M, C, K, Fk, Fc = model.matrices(p)
    return mo.qdd @ M.T + mo.qd @ C.T + mo.q @ K.T - mo.r @ Fk.T - mo.rd @ Fc.T


def force_sensitivity(model: SuspensionModel, p: Mapping[str, float], mo: Motion,
                      name: str) -> FloatArray:
    """``dR/d theta`` for parameter ``name`` (central difference; exact where linear)."""
    dp = 1e-4 * p[name]
    hi, lo = dict(p), dict(p)
    hi[name] += dp
    lo[name] -= dp
    return (residual_force(model, hi, mo) - residual_force(model, lo, mo)) / (2 * dp)


# ------------------------------------------------------------------------- screening
@dataclass
class Screen:
    """Screening of one candidate effect: ``explained`` share (0..1) beyond the base parameters, ``tstat``,
    ``params``/``base`` (the refit's start), ``sites`` (``None``: every site), runners-up, per-strut fit.
    """

    name: str
    domain: str
    explained: float
    tstat: float
    plausible: bool
    params: dict[str, Any]
    base: dict[str, float] = field(default_factory=dict)
    note: str = ""
    sites: list[str] | None = None
    alternatives: list["Screen"] = field(default_factory=list)
    per_site: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        out = {"domain": self.domain, "explained": self.explained, "tstat": self.tstat,
               "plausible": self.plausible, "params": self.params, "note": self.note}
        if self.sites is not None:
            out["sites"] = list(self.sites)
        if self.per_site:
            out["per_site"] = dict(self.per_site)
        if self.alternatives:
            out["alternatives"] = [{"params": a.params, "explained": a.explained}
                                   for a in self.alternatives]
        return out


def _regress(y: FloatArray, X: FloatArray) -> tuple[FloatArray, float, FloatArray]:
    """Least squares ``y ~ X``: coefficients, residual sum of squares, coefficient std errors."""
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    res = y - X @ beta
    ss = float(res @ res)
    dof = max(y.size - X.shape[1], 1)
    try:
        cov = np.linalg.pinv(X.T @ X) * ss / dof
        se = np.sqrt(np.clip(np.diag(cov), 0, None))
    except np.linalg.LinAlgError:
        se = np.full(X.shape[1], np.inf)
    return np.asarray(beta, dtype=float), ss, np.asarray(se, dtype=float)


def _refined(p: Mapping[str, float], names: list[str], delta: FloatArray) -> dict[str, float]:
    """``p`` with each of ``names`` moved by ``-delta`` where that stays positive."""
    out = dict(p)
    for k, d in zip(names, delta):
        if p[k] - d > 0:
            out[k] = float(p[k] - d)
    return out


def velocity_noise(mo: Motion, noise_var: Mapping[str, float], coords: tuple[str, ...] | list[str],
                   h: float) -> FloatArray:
    """Per-coordinate std of the white noise left in the smoothed velocities ``mo.qd``."""
    n = mo.qd.shape[0]
    w = _savgol_window(n, 1.0 / h)
    g0 = float(np.sum(savgol_coeffs(w, 3) ** 2))
    g1 = float(np.sum(savgol_coeffs(w, 3, deriv=1, delta=h) ** 2))
    out = np.zeros(len(coords))
    for i, c in enumerate(coords):
        src = mo.source.get(f"{c}_dot")
        if src == "measured":
            out[i] = math.sqrt(max(float(noise_var.get(f"{c}_dot", 0.0)), 0.0) * g0)
        elif src == "derived":
            out[i] = math.sqrt(max(float(noise_var.get(c, 0.0)), 0.0) * g1)
    return out


def screen_physical(model: SuspensionModel, p: Mapping[str, float], free: list[str], mo: Motion,
                    noise_var: Mapping[str, float], h: float) -> tuple[list[Screen], dict[str, Any]]:
    """Regress the residual force on base sensitivities plus each registered physical candidate.

    Each effect is tried in the library's form and in each strut alone; the best plausible form is
    kept. Returns the screens and the force-domain summary.
    """
    R = residual_force(model, p, mo)
    nq = R.shape[1]
    n = R.shape[0]
    qd_noise = (velocity_noise(mo, noise_var, model.coords, h) if noise_var and h
                else np.zeros(nq))
    wrow = 1.0 / np.maximum(np.sqrt(np.mean(R ** 2, axis=0)), 1e-12)
    y = (R * wrow).reshape(-1)
    base_names = [k for k in free if k in p]
    D = [(force_sensitivity(model, p, mo, k) * wrow).reshape(-1) for k in base_names]
    X0 = np.column_stack(D) if D else np.zeros((y.size, 0))
    _, ss0, _ = _regress(y, X0) if D else (np.zeros(0), float(y @ y), np.zeros(0))
    ss_raw = float(y @ y)
    neff = effective_n(y[: n])  # serial correlation of the first equation
    infl = math.sqrt(max(n / neff, 1.0))
    screens: list[Screen] = []
    Xs = np.column_stack([mo.q, mo.qd])
    Us = np.column_stack([mo.r, mo.rd])

    def fit_columns(cols: list[FloatArray]) -> tuple[FloatArray, float, FloatArray, dict[str, float]] | None:
        """Regress on base sensitivities plus ``cols``: (coef, explained, coef se, refined base)."""
        E = [(c * wrow).reshape(-1) for c in cols]
        if not E or any(not np.any(e) for e in E):
            return None
        X = np.column_stack([X0] + [e[:, None] for e in E]) if D else np.column_stack(E)
        beta, ss1, se = _regress(y, X)
        explained = max(0.0, (ss0 - ss1) / ss0) if ss0 > 0 else 0.0
        return beta[len(D):], explained, se[len(D):] * infl, _refined(p, base_names, beta[: len(D)])

    def rate_noise(site: Site) -> float:
        """Standard deviation (m/s) of the noise in the smoothed rate at ``site``."""
        return float(np.sqrt(np.sum((site.g * qd_noise) ** 2)))

    def site_columns(cls: type[PhysicalEffect], sites: list[Site], trial: Trial) -> list[FloatArray]:
        """One column per regressor, summed over ``sites`` (shared parameters)."""
        cols: list[FloatArray] = []
        for site in sites:
            s, sd = site.coordinate(Xs, Us)
            for j, reg in enumerate(cls.regressors(site, s, sd, p, trial, rate_noise(site))):
                while len(cols) <= j:
                    cols.append(np.zeros((n, nq)))
                cols[j] = cols[j] + np.asarray(reg, dtype=float)[:, None] * site.b[None, :]
        return cols

    for name, cls in effect_classes().items():
        if not issubclass(cls, PhysicalEffect):
            continue
        try:
            every = cls.model_sites(model, p)
        except UsageError:
            continue
        if not every:
            continue
        variants: list[list[Site] | None] = [None] if cls.sites_problem(every) is None else []
        if cls.site_kind == "strut" and len(every) > 1:
            variants += [[site] for site in every]
        best: Screen | None = None
        best_trial: Trial = {}
        for var in variants:
            sites = every if var is None else var
            coords = [site.coordinate(Xs, Us) for site in sites]
            trials = cls.screen_trials(sites, [c[0] for c in coords], [c[1] for c in coords])
            for trial in trials:
                fitted = fit_columns(site_columns(cls, sites, trial))
                if fitted is None:
                    continue
                coef, explained, cse, refined = fitted
                tstat = float(np.max(np.abs(coef) / np.maximum(cse, 1e-300)))
                params, plausible, note = cls.from_coefficients(
                    coef, refined, trial, sites, [rate_noise(site) for site in sites])
                cand = Screen(name, "force", explained, tstat, plausible, params, refined, note,
                              sites=None if var is None else [site.name for site in var])
                if best is None or (cand.plausible, cand.explained) > (best.plausible, best.explained):
                    best, best_trial = cand, trial
        if best is None:
            continue
        if cls.site_kind == "strut" and len(every) > 1:
            # diagnostic: one coefficient per strut (do the struts agree?)
            cols = [c for site in every for c in site_columns(cls, [site], best_trial)]
            fitted = fit_columns(cols)
            if fitted is not None:
                coef, explained, cse, _ = fitted
                k = len(cols) // len(every)
                per = [cls.from_coefficients(coef[i * k:(i + 1) * k], best.base, best_trial, [site],
                                             [rate_noise(site)])
                       for i, site in enumerate(every)]
                best.per_site = {"explained": explained,
                                 "plausible": all(ok for _, ok, _ in per),
                                 "sites": {site.name: prm for site, (prm, _, _) in zip(every, per)}}
        screens.append(best)
    summary = {"rms_force": {c: float(v) for c, v in zip(model.coords, np.sqrt(np.mean(R ** 2, axis=0)))},
               "base_refit_explained": float(1 - ss0 / ss_raw) if ss_raw > 0 else 0.0,
               "samples": n, "effective_samples": neff}
    return screens, summary


def output_residuals(meas: Measurement, predicted: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
    """``measured - predicted`` of every measured channel the model predicts (not all NaN)."""
    resid = {c: np.asarray(meas.measured[c], dtype=float) - np.asarray(predicted[c], dtype=float)
             for c in meas.measured if c in predicted}
    return {c: e for c, e in resid.items() if np.any(~np.isnan(e))}


def output_regression(cls: type[SensorEffect], group: Sequence[str], t: FloatArray,
                      resid: Mapping[str, FloatArray], predicted: Mapping[str, FloatArray]
                      ) -> tuple[float, float, float] | None:
    """Pooled regression ``e_c ~ beta r_c`` of the group's output residual: ``(beta, share, tstat)``
    or ``None``.
    """
    used: list[tuple[FloatArray, FloatArray]] = []
    for c in group:
        if c not in resid:
            continue
        r = cls.output_sensitivity(c, t, predicted)
        if r is None:
            continue
        r = np.asarray(r, dtype=float)
        e = resid[c]
        ok = ~(np.isnan(e) | np.isnan(r))
        if ok.sum() >= 3 and np.any(r[ok]):
            used.append((e[ok], r[ok]))
    if not used:
        return None
    er = sum(float(np.mean(e * r)) for e, r in used)
    rr = sum(float(np.mean(r * r)) for _, r in used)
    beta = er / rr
    share = 0.0
    for e, r in used:
        ms = float(np.mean(e ** 2))
        if ms > 0:
            share += beta * beta * float(np.mean(r * r)) / ms
    share /= max(len(resid), 1)
    ss = sum(float(np.mean((e - beta * r) ** 2)) for e, r in used)
    se = math.sqrt(ss / rr) / math.sqrt(effective_n(used[0][0]))
    return beta, share, abs(beta) / max(se, 1e-300)


def screen_sensor(model: SuspensionModel, meas: Measurement, p: Mapping[str, float], free: list[str],
                  predicted: Mapping[str, FloatArray], U: FloatArray,
                  max_delay: float) -> list[Screen]:
    """Screen every registered sensor effect: one :class:`Screen` per effect with a candidate."""
    out: list[Screen] = []
    resid = output_residuals(meas, predicted)
    for cls in effect_classes().values():
        if not issubclass(cls, SensorEffect):
            continue
        if cls.time_shift:
            sc = screen_time_shift(cls, model, meas, p, free, predicted, U, max_delay)
            if sc is not None:
                out.append(sc)
            continue
        best: Screen | None = None
        for g in cls.screen_groups(model, list(resid)):
            fitted = output_regression(cls, g, meas.t, resid, predicted)
            if fitted is None:
                continue
            value, share, tstat = fitted
            params = cls.params_from_screen(g, value, max_delay)
            cand = Screen(cls.name, "output", share if params is not None else 0.0, tstat,
                          params is not None, params or {})
            if best is None or (cand.plausible, cand.explained) > (best.plausible, best.explained):
                best = cand
        if best is not None:
            out.append(best)
    return out


def screen_time_shift(cls: type[SensorEffect], model: SuspensionModel, meas: Measurement,
                      p: Mapping[str, float], free: list[str], predicted: Mapping[str, FloatArray],
                      U: FloatArray, max_delay: float) -> Screen | None:
    """Screen a time shift of each channel group against the others (``sensor_delay``) in the residual
    force and in the output residual; close runners-up go to :attr:`Screen.alternatives`.
    """
    t = meas.t
    h = float(np.median(np.diff(t)))
    mo0 = motion_from(model, meas, predicted, U)
    R0 = residual_force(model, p, mo0)
    wrow = 1.0 / np.maximum(np.sqrt(np.mean(R0 ** 2, axis=0)), 1e-12)
    base_names = [k for k in free if k in p]
    trim = int(math.ceil(max_delay / h)) + 2

    def regress_for(m: Motion) -> tuple[float, dict[str, float]]:
        R = residual_force(model, p, m)[:-trim]
        y = (R * wrow).reshape(-1)
        if not base_names:
            return float(y @ y), dict(p)
        sub = Motion(m.q[:-trim], m.qd[:-trim], m.qdd[:-trim], m.r[:-trim], m.rd[:-trim], m.source)
        X = np.column_stack([(force_sensitivity(model, p, sub, k) * wrow).reshape(-1) for k in base_names])
        beta, ss, _ = _regress(y, X)
        return ss, _refined(p, base_names, beta)

    ss0 = regress_for(mo0)[0]
    shifted: dict[tuple[int, float], Motion] = {}
    groups = cls.screen_groups(model, list(meas.measured))
    grid = [d for d in h * np.array([0.5, 1, 1.5, 2, 3, 4, 6, 8, 11, 16, 22, 32]) if d <= max_delay]
    feeds: list[tuple[str, int, str]] = []
    for i, c in enumerate(model.coords):
        for kind, chain in (("q", (c,)), ("qd", (f"{c}_dot", c)), ("qdd", (f"{c}_ddot", f"{c}_dot", c))):
            for ch in chain:
                if mo0.source.get(ch if kind == "q" else f"{c}{'_dot' if kind == 'qd' else '_ddot'}") == "model":
                    break
                if ch in meas.measured:
                    feeds.append((kind, i, ch))
                    break
    # a channel lagging by d reads y - d y': the output residual scores the lag too
    resid = output_residuals(meas, predicted)

    n_out = max(len(resid), 1)

    def output_screen(g: list[str]) -> tuple[float, float]:
        """(share of the channel-normalised output residual, delay) of a common lag of ``g``."""
        num, den, nobs = 0.0, 0.0, 0
        for c in g:
            if c not in resid:
                continue
            r = cls.output_sensitivity(c, t, predicted)   # -d y/dt: a lag d reads y - d y'
            if r is None:
                continue
            r = np.asarray(r, dtype=float)
            e = resid[c]
            ok = ~(np.isnan(e) | np.isnan(r))
            ok[-trim:] = False
            var = float(np.mean(e[ok] ** 2)) if ok.any() else 0.0
            if var <= 0:
                continue
            num += float(e[ok] @ r[ok]) / var
            den += float(r[ok] @ r[ok]) / var
            nobs = max(nobs, int(ok.sum()))
        if den <= 0 or nobs == 0:
            return 0.0, 0.0
        d = num / den
        if cls.params_from_screen(g, d, max_delay) is None:
            return 0.0, d
        return (num * num / den) / (nobs * n_out), d

    # (score, group index, ss per grid point, output share, output delay)
    per_group: list[tuple[float, int, list[float], float, float]] = []
    for gi, g in enumerate(groups):
        cols = [(kind, i) for kind, i, ch in feeds if ch in g]
        sss = []
        for d in grid if cols else []:
            arrs = {"q": mo0.q.copy(), "qd": mo0.qd.copy(), "qdd": mo0.qdd.copy()}
            for kind, i in cols:
                a = arrs[kind]
                a[:, i] = shift_allpass(t, a[:, i], d)  # advance; the tail is trimmed
            m2 = Motion(arrs["q"], arrs["qd"], arrs["qdd"], mo0.r, mo0.rd, mo0.source)
            shifted[(gi, float(d))] = m2
            sss.append(regress_for(m2)[0])
        f_share = max(0.0, (ss0 - min(sss)) / ss0) if sss and ss0 > 0 else 0.0
        o_share, o_delay = output_screen(g)
        if not sss and o_share <= 0:
            continue
        per_group.append((max(f_share, o_share), gi, sss, o_share, o_delay))
    if not per_group:
        return None
    per_group.sort(key=lambda r: -r[0])

    def screen_of(gi: int, sss: list[float], o_share: float, o_delay: float) -> Screen:
        g = groups[gi]
        f_share = max(0.0, (ss0 - min(sss)) / ss0) if sss and ss0 > 0 else 0.0
        if o_share > f_share:
            return Screen(cls.name, "output", o_share, float("nan"), True,
                          cls.params_from_screen(g, o_delay, max_delay) or {}, dict(p),
                          note=f"time shift of {', '.join(g)} against the other channels, from "
                               "the output residual against the model's rate")
        i = int(np.argmin(sss))
        d = float(grid[i])
        if 0 < i < len(grid) - 1:
            x = np.array(grid[i - 1:i + 2])
            yv = np.array(sss[i - 1:i + 2])
            A = np.vstack([x ** 2, x, np.ones(3)]).T
            a, b, _ = np.linalg.solve(A, yv)
            if a > 0 and x[0] < -b / (2 * a) < x[2]:
                d = float(-b / (2 * a))
        _, refined = regress_for(shifted[(gi, float(grid[i]))])
        return Screen(cls.name, "force", f_share, float("nan"), True,
                      cls.params_from_screen(g, d, max_delay) or {}, refined,
                      note=f"time shift of {', '.join(g)} against the other channels, from the "
                           "residual force")

    best = screen_of(*per_group[0][1:])
    # near ties between channel groups are common: keep close runners-up for the refit to decide
    g0 = groups[per_group[0][1]]
    closure = next((gi for gi, g in enumerate(groups)
                    if len(g0) == 1 and len(g) > 1 and g0[0] in g), None)
    for row in per_group[1:]:
        alt = screen_of(*row[1:])
        if row[1] == closure or alt.explained >= 0.8 * best.explained:
            best.alternatives.append(alt)
        if len(best.alternatives) >= 2:
            break
    return best
