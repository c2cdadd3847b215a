"""Sliding-window identification: one warm-started, budgeted Nelder-Mead fit per window.

Each window is an :class:`~estimator.identify.OutputErrorProblem` fitted with
:func:`~estimator.identify.minimize_log` and given ``suspid identify``'s sandwich standard
errors; later windows start from the last estimates' trend with a small fresh simplex. A
window lacking samples or excitation is skipped with the reason. Settings and measurements:
:mod:`estimator.stream.config`, ``docs/monitoring.md``.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Mapping

import numpy as np
# scipy.signal is reached lazily: only a monitor with the road low-pass loads it
import scipy

from estimator.identify import OutputErrorProblem, Parameters, minimize_log
from estimator.identify.profile import SIGMAS
from estimator.identify.misfit import (EXACT_FIT, noise_floor_ratios, ratios_of_parts,
                                       residual_noise_floor_parts)
from estimator.identify.multistart import twin_of
from estimator.identify.start import cold_start
from estimator.stream.config import WindowConfig
from estimator.stream.windowfit import WindowFit, drift_cov
from suspid.errors import UsageError
from suspid.io.csvio import Measurement
from suspid.models.base import AffinePieces, FloatArray, SuspensionModel
from suspid.simulate import uniform_step


@dataclass
class WindowResult:
    """Outcome of one window ending at data time ``t`` (s): the parameters (SI), their stderr
    with the ``sigma_floor`` and the fit's own (``stderr_fit``), evaluations, cost, CPU time,
    ``excitation`` and per-channel ``noise_floor_ratio``; or ``skipped`` with the ``reason``."""

    t: float
    t_start: float
    skipped: bool = False
    params: dict[str, float] = field(default_factory=dict)
    stderr: dict[str, float] = field(default_factory=dict)
    stderr_fit: dict[str, float] = field(default_factory=dict)
    nfev: int = 0
    budget: int = 0
    converged: bool = False
    identifiable: bool = True
    cost: float = float("nan")
    rms_residual: dict[str, float] = field(default_factory=dict)
    cpu_s: float = 0.0
    excitation: dict[str, float] = field(default_factory=dict)
    noise_floor_ratio: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    reason: str = ""

    def to_json(self) -> dict[str, Any]:
        """The monitor's JSON line (``estimate`` or ``skip``)."""
        if self.skipped:
            return {"type": "skip", "t": self.t, "t_start": self.t_start, "reason": self.reason,
                    "excitation": self.excitation}
        return {"type": "estimate", "t": self.t, "t_start": self.t_start,
                "params": self.params, "stderr": self.stderr, "stderr_fit": self.stderr_fit,
                "nfev": self.nfev, "budget": self.budget, "converged": self.converged,
                "identifiable": self.identifiable, "cost": self.cost,
                "rms_residual": self.rms_residual, "cpu_ms": 1e3 * self.cpu_s,
                "excitation": self.excitation, "noise_floor_ratio": self.noise_floor_ratio,
                "warnings": self.warnings}


def _finite(y: FloatArray) -> FloatArray:
    """``y`` without its NaN/inf samples (``y`` itself when every sample is finite)."""
    return y if math.isfinite(float(np.add.reduce(y))) else y[np.isfinite(y)]


def _std(y: FloatArray) -> float:
    """Population standard deviation (as :func:`numpy.std`, without its call overhead)."""
    d = y - float(np.add.reduce(y)) / y.size
    return math.sqrt(float(d @ d) / y.size)


def noise_floor(y: FloatArray) -> float:
    """White-noise standard deviation of ``y`` from its fourth difference (same units):
    ``var(diff4(e)) = 70 var(e)`` for white ``e``, smooth motion contributes little."""
    y = _finite(y)
    if y.size < 10:
        return float("nan")
    return _std(np.diff(y, 4)) / math.sqrt(70.0)


def _missing(v: FloatArray) -> float:
    """Fraction of the samples of ``v`` missing (NaN/inf) at its own cadence: a channel
    filling every ``N``-th cell (a multiplexed page, a slower message) misses nothing then."""
    if math.isfinite(float(np.add.reduce(v))):
        return 0.0
    at = np.flatnonzero(np.isfinite(v))
    if at.size < 2:
        return 1.0 - at.size / v.size
    step = int(np.median(np.diff(at)))
    expected = -(-v.size // step)
    return max(0.0, 1.0 - at.size / expected)


def fuse_road(t: FloatArray, r: FloatArray, r_dot: FloatArray, crossover_hz: float) -> FloatArray:
    """Road displacement (m) from its measurement ``r`` below ``crossover_hz`` and the integral
    of its velocity ``r_dot`` (m/s) above, on uniform times ``t`` (s).

    ``r_hat = R + LP(r - R)``, ``R`` the trapezoidal integral of ``r_dot`` and ``LP`` a centred
    moving average of ``1 / crossover_hz`` s applied twice: white noise on ``r`` (an input
    error that biases the dampers) is averaged out. A non-finite sample leaves ``r`` as it is.
    """
    r = np.asarray(r, dtype=float)
    v = np.asarray(r_dot, dtype=float)
    if r.size < 3 or not (np.isfinite(r).all() and np.isfinite(v).all()):
        return r
    h = float(t[1] - t[0])
    # at most the window itself
    w = min(2 * int(round(0.5 / (crossover_hz * h))) + 1, r.size - 1 + r.size % 2)
    if w < 3:
        return r
    R = np.concatenate(([0.0], np.cumsum(0.5 * h * (v[1:] + v[:-1]))))
    dlt = r - R
    k = np.ones(w)
    one = np.ones(r.size)
    for _ in range(2):
        dlt = np.convolve(dlt, k, mode="same") / np.convolve(one, k, mode="same")
    return np.asarray(R + dlt, dtype=float)


@lru_cache(maxsize=32)
def _butter_sos(order: int, wn: float) -> FloatArray:
    """Second-order sections of a Butterworth low-pass (``wn``: cutoff / Nyquist)."""
    return np.asarray(scipy.signal.butter(order, wn, output="sos"), dtype=float)


def lowpass_road(v: FloatArray, h: float, cutoff_hz: float) -> FloatArray:
    """Zero-phase second-order Butterworth low-pass (``sosfiltfilt``, -6 dB at ``cutoff_hz``, odd padding of
    ``3 / cutoff_hz`` s) of one road channel sampled every ``h`` s; unchanged when a sample is
    not finite, the cutoff is at or above 0.9 x Nyquist or the window is shorter than the pad."""
    v = np.asarray(v, dtype=float)
    wn = 2.0 * cutoff_hz * h
    pad = int(math.ceil(3.0 / (cutoff_hz * h))) if cutoff_hz > 0 else 0
    if not 0 < wn < 0.9 or v.size <= pad + 1 or not math.isfinite(float(np.add.reduce(v))):
        return v
    return np.asarray(scipy.signal.sosfiltfilt(_butter_sos(2, wn), v, padtype="odd", padlen=pad),
                      dtype=float)


class SlidingWindowIdentifier:
    """Fit the free parameters of ``params`` on successive windows of the measured ``channels``."""

    #: the drift fit to first order (:meth:`_drift_linear`); ``False``: Gauss-Newton only
    first_order_drift: bool = True

    def __init__(self, model: SuspensionModel, params: Parameters, config: WindowConfig,
                 channels: list[str]) -> None:
        self.model = model
        self.config = config
        self.channels = [c for c in model.channels if c in channels]
        if not self.channels:
            raise UsageError(f"no measured channel of model {model.name} in the stream; "
                             f"expected some of {', '.join(model.channels)}")
        self.params = params.copy()
        self.free = self.params.free
        self.nominal = self.params.valuesdict()
        #: the forward model's affine pieces in the free parameters, once per monitor
        self._affine: AffinePieces | None
        try:
            self._affine = model.affine(self.nominal, self.free)
        except (np.linalg.LinAlgError, ValueError, ZeroDivisionError, FloatingPointError):
            self._affine = None  # each window's problem builds its own from its parameters
        fixed_drift = [k for k in config.drift if k not in self.free]
        if fixed_drift:
            raise UsageError(f"drift: {', '.join(fixed_drift)} not among the free parameters "
                             f"({', '.join(self.free)})")
        #: previous accepted estimate (SI) and its relative stderr_fit per free parameter
        self._warm: tuple[dict[str, float], dict[str, float]] | None = None
        #: (window end time (s), log of the free parameters) of the last accepted windows
        self._hist: list[tuple[float, list[float]]] = []
        self.n_windows = 0
        self.n_skipped = 0
        self.total_nfev = 0
        self.total_cpu = 0.0
        probe = {c: np.zeros(1) for c in self.channels}
        #: struts whose deflection the measured position channels give
        self._struts = list(model.deflections(probe, self.nominal))
        self._motion = next((c for c in self.channels if c in model.coords), self.channels[0])

    def excitation(self, t: FloatArray, data: Mapping[str, FloatArray]) -> tuple[dict[str, float], str]:
        """Excitation statistics of a window and the reason to skip it (``""`` to fit)."""
        cfg = self.config
        needed = list(self.channels) + [r for r in self.model.roads if r in data]
        worst = max(((_missing(data[c]), c) for c in needed), default=(0.0, ""))
        ex: dict[str, float] = {"missing": worst[0]}
        if worst[0] > cfg.max_missing:
            return ex, (f"channel {worst[1]}: {worst[0]:.0%} of the window's samples missing "
                        f"(> {cfg.max_missing:.0%}); gap in the data")
        h = uniform_step(t)
        if h is None:
            d = np.diff(t)
            k = int(np.argmax(d))
            return ex, (f"time base not uniform: step {d[k]:.4g} s at t={t[k]:.3f} s "
                        f"(median {np.median(d):.4g} s)")
        defl = {k: v for k, v in self.model.deflections(
            {c: data[c] for c in self.channels}, self.nominal).items() if k in self._struts}
        if defl:
            name, y = max(defl.items(), key=lambda kv: _std(_finite(kv[1])) if kv[1].size else 0.0)
            what = f"suspension deflection ({name})"
        else:
            y = data[self._motion]
            what = f"motion {self._motion}"
        yf = _finite(y)
        rms = _std(yf) if yf.size else 0.0
        nf = noise_floor(y)
        snr = rms / nf if nf > 0 else math.inf
        ex.update({"deflection_rms": rms, "noise": nf, "snr": snr})
        is_pos = bool(defl) or (self._motion in self.model.coords)
        if is_pos and rms < cfg.min_deflection:
            return ex, (f"too little excitation: {what} RMS {rms * 1e3:.3g} mm < "
                        f"{cfg.min_deflection * 1e3:.3g} mm")
        if snr < cfg.min_snr:
            return ex, (f"too little excitation: {what} RMS is {snr:.3g} x the noise floor "
                        f"({nf:.3g}), below {cfg.min_snr:g}")
        return ex, ""

    def _problem(self, t: FloatArray, data: Mapping[str, FloatArray]) -> OutputErrorProblem:
        d = self.config.decimate
        fc, lp = self.config.road_fusion_hz, self.config.road_lowpass_hz
        full = dict(data)
        for r in self.model.roads:
            if fc > 0 and r in data and f"{r}_dot" in data:
                full[r] = fuse_road(t, data[r], data[f"{r}_dot"], fc)
            if lp > 0 and t.size > 1 and r in full:
                full[r] = lowpass_road(full[r], float(t[1] - t[0]), lp)
        road = {k: np.asarray(full[k][::d], dtype=float) for k in
                list(self.model.roads) + [f"{r}_dot" for r in self.model.roads] if k in full}
        meas = Measurement(t[::d].copy(), road,
                           {c: np.asarray(data[c][::d], dtype=float) for c in self.channels},
                           source="window")
        return OutputErrorProblem(self.model, meas, cost=self.config.cost, affine=self._affine,
                                  ride_heights=False)

    def _predict(self, t_end: float) -> list[float] | None:
        """Log of the free parameters extrapolated to ``t_end`` along the line through the last
        (up to 3) estimates of consecutive windows, capped at 5 %; ``None`` otherwise."""
        cfg = self.config
        h = self._hist
        if len(h) < 2:
            return None
        ts = [a for a, _ in h]
        gap = 1.5 * cfg.step_s
        if any(b - a > gap for a, b in zip(ts, ts[1:])) or t_end - ts[-1] > gap:
            return None
        tm = sum(ts) / len(ts)
        stt = sum((a - tm) ** 2 for a in ts)
        out = []
        for i in range(len(h[0][1])):
            ls = [b[i] for _, b in h]
            lm = sum(ls) / len(ls)
            slope = sum((a - tm) * (b - lm) for a, b in zip(ts, ls)) / stt
            step = lm + slope * (t_end - tm) - ls[-1]
            out.append(ls[-1] + min(0.05, max(-0.05, step)))
        return out

    def _start(self, t_end: float) -> tuple[Parameters, FloatArray | None, bool]:
        """Starting parameters, initial simplex (or ``None``) and whether this is a warm start:
        the predicted (:meth:`_predict`) or last estimate, with an axis-aligned simplex of edge
        ``max(warm_step, 3 x relative stderr_fit)`` (log units) centred on it."""
        p = self.params.copy()
        if self._warm is None:
            return p, None, False
        values, rel_se = self._warm
        pred = self._predict(t_end)
        for i, k in enumerate(self.free):
            p[k].value = values[k] if pred is None else float(math.exp(pred[i]))
        n = len(self.free)
        edge = [min(0.3, max(self.config.warm_step, 3.0 * rel_se.get(k, 0.0))) for k in self.free]
        sim = np.zeros((n + 1, n))
        sim[1:] = np.diag(edge)
        sim -= sim.mean(axis=0)
        return p, sim, True

    @staticmethod
    def _to_end(drift: list[str], g: list[float], half: float, out: WindowResult,
                why: str) -> None:
        """Carry constant-window estimates of ``drift`` to the window end at the recent rates
        ``g`` (1/s) when the drift fit is not possible."""
        for k, gk in zip(drift, g):
            f = math.exp(max(-0.2, min(0.2, gk * half)))
            out.params[k] *= f
            out.stderr[k] *= f
            out.stderr_fit[k] *= f
        out.warnings.append(f"{why}; the constant-window estimate of "
                            f"{', '.join(drift)} moved to the window end at the recent rate")

    def _drift_linear(self, fit: WindowFit, t_end: float, half: float,
                      p_const: Mapping[str, float], drift: list[str], b_prior: FloatArray,
                      has_prior: bool, out: WindowResult) -> bool:
        """The drift fit to first order around the constant fit; ``False``: not applicable.

        The residual is taken linear in ``a = log(theta_end / theta_const)`` and ``b = g width
        / 2`` (:meth:`~estimator.stream.windowfit.WindowFit.drift_sensitivity`); with the rate
        prior's rows, one linear least-squares solve gives both, and the stderr are
        Gauss-Newton ones on the same Jacobian. No evaluation of the drifting window.
        """
        cfg = self.config
        jac = fit.jacobian
        R0 = fit.residual(p_const)
        if jac is None or R0 is None or jac[0] != self.free or jac[1] != dict(p_const):
            return False
        sens = fit.drift_sensitivity(p_const, drift, t_end)
        if sens is None:
            return False
        Ja, Jg = sens
        nd = len(drift)
        pch, N = R0.shape
        sd_u = cfg.drift_rate_sd * half if has_prior else 0.0
        sig = (np.maximum(np.sqrt((R0 * R0).mean(axis=1)), 1e-300) if sd_u > 0
               else np.ones(pch))
        w = np.repeat(1.0 / sig, N)[:, None]
        r0 = R0.ravel()
        Jb = Jg / half
        # weighted least squares in x = (a, b), the prior's rows included
        M = np.hstack([Ja, Jb]) * w
        rhs = r0 * w[:, 0]
        if sd_u > 0:
            P = np.zeros((nd, 2 * nd))
            P[:, nd:] = np.eye(nd) / sd_u
            M = np.vstack([M, P])
            rhs = np.concatenate([rhs, b_prior / sd_u])
        Q, Rq = np.linalg.qr(M)
        x = np.asarray(np.linalg.solve(Rq, Q.T @ rhs), dtype=float)
        a, b = x[:nd], x[nd:]
        if not (np.all(np.isfinite(x)) and np.all(np.abs(x) < 0.5)):
            return False
        R = (r0 - Ja @ a - Jb @ b).reshape(pch, N)
        # stderr: every free parameter's column (the drifting ones' Ja) and the rates'
        cols = jac[2].copy()
        for j, k in enumerate(drift):
            cols[:, self.free.index(k)] = Ja[:, j]
        cols = np.hstack([cols, Jg])
        cov = drift_cov(cols, R, len(self.free), cfg.drift_rate_sd if sd_u > 0 else None)
        if cov is None:
            return False
        got = []
        for j, k in enumerate(drift):
            pk = p_const[k] * math.exp(float(a[j]))
            i = self.free.index(k)
            se = pk * math.sqrt(max(float(cov[i, i]), 0.0))
            if not (math.isfinite(se) and se > 0):
                return False
            got.append((k, pk, se))
        self._drift_result(fit, R, out, got)
        return True

    def _drift_result(self, fit: WindowFit, R: FloatArray, out: WindowResult,
                      got: list[tuple[str, float, float]]) -> None:
        """Set the drifting parameters' ``(name, end value, stderr_fit)`` (SI) and the noise-floor
        ratios of the drifting fit's residual ``R`` (channels x samples)."""
        for k, pk, se in got:
            out.params[k] = pk
            out.stderr_fit[k] = se
            out.stderr[k] = float(math.hypot(se, self.config.sigma_floor * pk))
        out.noise_floor_ratio = ratios_of_parts(
            residual_noise_floor_parts(np.asarray(R, dtype=float).T, fit.problem.channels))

    def _drift_fit(self, fit: WindowFit, t_end: float, width: float,
                   p_const: Mapping[str, float], drift: list[str], out: WindowResult) -> None:
        """Refit ``drift`` with a linear drift over the window; their values at its end.

        First order when it applies (:meth:`_drift_linear`), else a few Gauss-Newton steps in
        ``log(theta_end / theta_const)`` and ``g width / 2`` from the recent rate, the other
        parameters held at the constant fit; stderr with the rates free.
        """
        cfg = self.config
        chunk = cfg.drift_chunk_s
        half = 0.5 * width
        h = self._hist
        nd = len(drift)
        u = np.zeros(2 * nd)
        g_hist = [0.0] * nd
        if len(h) >= 2 and h[-1][0] > h[0][0]:
            for j, k in enumerate(drift):
                i = self.free.index(k)
                g_hist[j] = (h[-1][1][i] - h[0][1][i]) / (h[-1][0] - h[0][0])
                u[j] = u[nd + j] = max(-0.2, min(0.2, g_hist[j] * half))

        def unpack(v: FloatArray) -> tuple[dict[str, float], dict[str, float]]:
            p = dict(p_const)
            rates = {}
            for j, k in enumerate(drift):
                p[k] = p_const[k] * math.exp(float(v[j]))
                rates[k] = float(v[nd + j]) / half
            return p, rates

        def resid(v: FloatArray) -> FloatArray | None:
            p, rates = unpack(v)
            try:
                return fit.drift_residual(p, rates, t_end, chunk)
            except (np.linalg.LinAlgError, ValueError, FloatingPointError, OverflowError):
                return None

        if self.first_order_drift and self._drift_linear(
                fit, t_end, half, p_const, drift, u[nd:].copy(), len(h) >= 2, out):
            return
        step = 1e-4
        R = resid(u)
        ok = R is not None
        # optional prior on the rates: the recent estimates' rate, sd drift_rate_sd (1/s)
        sd_u = cfg.drift_rate_sd * half if len(h) >= 2 else 0.0
        u_prior = u[nd:].copy()
        # with a prior the residuals are weighted by their channel's RMS (noise units)
        sig = (np.ones(1) if R is None or sd_u == 0 else
               np.maximum(np.sqrt((R * R).mean(axis=1)), 1e-300))[:, None]

        def objective(Rv: FloatArray, v: FloatArray) -> float:
            ss = float(((Rv / sig) ** 2).sum())
            if sd_u > 0:
                ss += float((((v[nd:] - u_prior) / sd_u) ** 2).sum())
            return ss
        for _ in range(cfg.drift_iterations):
            if R is None:
                break
            cols = []
            for j in range(2 * nd):
                e = u.copy()
                e[j] += step
                Rj = resid(e)
                if Rj is None:
                    ok = False
                    break
                cols.append(((Rj - R) / step / sig).ravel())
            if not ok:
                break
            J = np.column_stack(cols)
            rhs = -(R / sig).ravel()
            if sd_u > 0:
                P = np.zeros((nd, J.shape[1]))
                P[:, nd:] = np.eye(nd) / sd_u
                J = np.vstack([J, P])
                rhs = np.concatenate([rhs, -(u[nd:] - u_prior) / sd_u])
            du = np.linalg.lstsq(J, rhs, rcond=None)[0]
            ss = objective(R, u)
            for _half in range(4):
                un = u + du
                Rn = resid(un) if np.all(np.abs(un) < 0.5) else None
                if Rn is not None and objective(Rn, un) < ss:
                    u, R = un, Rn
                    break
                du = 0.5 * du
            else:
                break
            if np.abs(du).max() < cfg.xatol:
                break
        if not ok or R is None:
            self._to_end(drift, g_hist, half, out, "drift fit not possible on this window")
            return
        p, rates = unpack(u)
        se = fit.drift_stderr(p, self.free, rates, t_end, chunk,
                              cfg.drift_rate_sd if sd_u > 0 else None, R)
        if se is None:
            self._to_end(drift, g_hist, half, out, "drift fit without stderr")
            return
        self._drift_result(fit, R, out, [(k, p[k], se[k]) for k in drift])

    def process(self, t: FloatArray, data: Mapping[str, FloatArray]) -> WindowResult:
        """Fit one window (times ``t``, s; channel and road arrays, SI, NaN where missing)."""
        c0 = time.process_time()
        out = WindowResult(t=float(t[-1]), t_start=float(t[0]))
        ex, reason = self.excitation(t, data)
        out.excitation = ex
        if reason:
            out.skipped, out.reason = True, reason
            self.n_skipped += 1
            out.cpu_s = time.process_time() - c0
            self.total_cpu += out.cpu_s
            return out
        cfg = self.config
        prob = self._problem(t, data)
        fit = WindowFit(prob)
        params, simplex, warm = self._start(float(t[-1]))
        if not warm:  # cold: the record's own estimate when the nominal start fits worse
            params = cold_start(self.model, prob.meas, params, self.config.cost)
        free = self.free
        th0 = [params[k].value for k in free]
        base = params.valuesdict()

        def to_params(u: FloatArray) -> dict[str, float]:
            p = dict(base)
            for k, a, x in zip(free, th0, u.tolist()):
                p[k] = a * math.exp(x)
            return p

        def cost(u: FloatArray) -> float:
            if not all(-30.0 < x < 30.0 for x in u.tolist()):
                return math.inf
            return prob.normalized_ss(to_params(u))

        budget = cfg.maxfev if warm else cfg.first_maxfev
        # termination on the simplex size alone (xatol): the cost's scale says nothing here
        nm = minimize_log(cost, np.zeros(len(free)), step=0.3,
                          restarts=0 if warm else cfg.first_restarts,
                          maxfev=budget, xatol=cfg.xatol, fatol=math.inf,
                          initial_simplex=simplex,
                          adaptive=None if cfg.warm_adaptive or not warm else False)
        converged = nm.nfev < budget
        p_hat = to_params(nm.u)
        final: list[Mapping[str, float]] | None = (
            None if nm.final_simplex is None else [to_params(v) for v in nm.final_simplex])
        nfev = nm.nfev
        jac = None
        if cfg.gauss_newton_step:
            gn = fit.gauss_newton(free, p_hat, cfg.gauss_newton_steps)
            nfev += gn.nfev
            jac = gn.jacobian
            if gn.params is not None:
                p_hat = gn.params
        # the first window: its fit's twin (SuspensionModel.twin) when that fits as well, within
        # 3 sigma of the noise (a cost rise of SIGMAS^2 residual variances), and the rule prefers it
        twin_note = None
        tw = None if warm else twin_of(prob, params, p_hat)
        if tw is not None and tw.prefer:
            c_fit, c_twin = prob.normalized_ss(p_hat), prob.normalized_ss(tw.params)
            if c_twin <= c_fit * (1.0 + SIGMAS ** 2 / max(prob.n_obs - len(free), 1)) + EXACT_FIT:
                vals = ", ".join(f"{k} = {p_hat[k]:.6g}" for k in free)
                twin_note = (f"the first window's fit ({vals}) has a twin that fits as well: the "
                             f"cost cannot tell {tw.swapped}; the twin is taken by the rule: {tw.rule}")
                # the simplex and Jacobian belong to the other fit
                p_hat, final, jac = tw.params, None, None
        res = fit.finish(params, p_hat, nfev, True, simplex=final, jacobian=jac)
        out.params = res.params
        out.stderr_fit = dict(res.stderr)
        out.stderr = {k: float(math.hypot(v, cfg.sigma_floor * res.params[k]))
                      for k, v in res.stderr.items()}
        out.nfev, out.budget, out.converged = nfev, budget, bool(converged)
        out.identifiable = bool(res.identifiable)
        out.cost = res.cost
        out.rms_residual = res.rms_residual
        # the constant fit's residual against white noise (a drift fit replaces it)
        out.noise_floor_ratio = noise_floor_ratios(prob, res.params)
        out.warnings = [w for w in res.warnings if "evaluation budget" not in w]
        if twin_note is not None:
            out.warnings.append(twin_note)
        if not converged:
            out.warnings.append(f"Nelder-Mead used its budget of {budget} evaluations "
                                f"before meeting xatol={cfg.xatol:g}")
        rel = {k: (v / res.params[k]) for k, v in res.stderr.items()}
        drift = [k for k in cfg.drift if k in free]
        if drift and res.identifiable:
            self._drift_fit(fit, float(t[-1]), float(t[-1] - t[0]), res.params, drift, out)
        if res.identifiable and all(np.isfinite(v) and v < 0.5 for v in rel.values()):
            self._warm = (dict(res.params), rel)
            self._hist = (self._hist + [(out.t, [math.log(res.params[k]) for k in free])])[-3:]
        self.n_windows += 1
        self.total_nfev += nfev
        out.cpu_s = time.process_time() - c0
        self.total_cpu += out.cpu_s
        return out
