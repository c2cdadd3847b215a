"""Output-only monitoring: the body mode from a body accelerometer alone.

The body bounce (natural frequency ``f_n``, damping ratio ``zeta``) shows in the
acceleration spectrum because the road is a broadband excitation. Two estimators:

``carma`` (default)
    The window's Welch spectrum (16 s Hann segments) fitted in log amplitude over
    0.3-5 Hz by the base-excited single mode under white road velocity,
    ``S_a(f) = K w^2 (w_n^4 + 4 zeta^2 w_n^2 w^2) / ((w_n^2 - w^2)^2 + 4 zeta^2 w_n^2 w^2) + B``.
``ar``
    AR(p) by least squares after decimation to 10 Hz; the pole pair in 0.5-4 Hz with the
    highest spectral peak is the body mode.

Results on synthetic and real records: docs/monitoring.md.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import decimate, welch

from estimator.stream.events import Estimate, Skip
from estimator.stream.monitor import StepResult
from suspid.errors import InputError, UsageError
from suspid.models.base import FloatArray

METHODS = ("carma", "ar")
#: band (Hz) the ``carma`` spectrum is fitted over (its top held below the Nyquist frequency)
CARMA_BAND = (0.3, 5.0)
#: band (Hz) the ``ar`` method looks for the body's pole pair in
AR_BAND = (0.5, 4.0)
#: damping ratios the ``carma`` fit searches between
ZETA_BOUNDS = (0.02, 1.5)
#: a fitted value within this relative distance of a search bound stopped there
AT_BOUND = 1e-3
#: highest fitted frequency as a share of the Nyquist frequency (Welch's lines near it are
#: bent by the logger's anti-alias filter)
NYQUIST_SHARE = 0.8
#: lowest top of a fitted band (Hz): below it the body mode (1-2 Hz) cannot be told apart
MIN_BAND_TOP = 2.5
#: mean body acceleration (m/s^2) above which the channel holds gravity or another axis:
#: a car's body cannot keep accelerating vertically
MAX_MEAN_ACCEL = 3.0
#: a run of this many identical samples (or more) is a frozen or invalid sensor value
STUCK_SAMPLES = 25
#: a window with more than this fraction of missing samples is skipped
MAX_MISSING = 0.1
#: a window whose acceleration RMS (m/s^2) is below this is skipped: a parked car
MIN_RMS = 0.02
#: order of the ``ar`` method's model and the rate (Hz) it decimates to
AR_ORDER = 6
AR_RATE = 10.0


@dataclass
class BodyMode:
    """Body-mode estimate of one window: natural frequency (Hz), damping ratio, their
    standard errors (NaN when not available), the method, and the search bound the fit
    stopped at (then the value is no estimate; ``""`` when none).
    """

    f_hz: float
    zeta: float
    f_se: float
    zeta_se: float
    method: str
    at_bound: str = ""


def carma_psd(f: FloatArray, fn: float, zeta: float) -> FloatArray:
    """Unit-gain body-acceleration spectrum shape under white road velocity (see module doc)."""
    w = 2 * np.pi * np.asarray(f, dtype=float)
    wn = 2 * np.pi * fn
    num = w ** 2 * (wn ** 4 + 4 * zeta ** 2 * wn ** 2 * w ** 2)
    den = (wn ** 2 - w ** 2) ** 2 + 4 * zeta ** 2 * wn ** 2 * w ** 2
    return num / den


def fit_carma(y: FloatArray, fs: float, band: tuple[float, float] = CARMA_BAND) -> BodyMode:
    """Fit the body mode to the Welch spectrum of ``y`` (m/s^2) sampled at ``fs`` (Hz).

    A fit stopped at a bound of its search returns that bound with no standard error,
    named in ``at_bound``.
    """
    y = np.asarray(y, dtype=float) - float(np.mean(y))
    nper = min(y.size, max(16, int(round(16.0 * fs))))
    f, P = welch(y, fs, nperseg=nper)
    m = (f >= band[0]) & (f <= band[1]) & (P > 0)
    f, P = f[m], P[m]
    if f.size < 8:
        raise ValueError(f"only {f.size} spectral lines in {band[0]}-{band[1]} Hz; window too short")
    lp = np.log(P)

    def res(th: FloatArray) -> FloatArray:
        fn, zeta, lk, lb = th
        return np.log(np.exp(lk) * carma_psd(f, fn, zeta) + np.exp(lb)) - lp

    best = None
    for fn0 in (0.8, 1.2, 1.6, 2.2):
        for z0 in (0.15, 0.3, 0.5):
            lk0 = math.log(float(np.median(P)) / float(carma_psd(np.array([fn0]), fn0, z0)[0]) * 0.5)
            th0 = [fn0, z0, lk0, math.log(float(np.min(P)))]
            r = least_squares(res, th0, bounds=([band[0], ZETA_BOUNDS[0], -80, -120],
                                                [band[1], ZETA_BOUNDS[1], 80, 80]))
            if best is None or r.cost < best.cost:
                best = r
    if best is None:  # pragma: no cover - the grid always yields a result
        raise ValueError("spectral fit failed")
    s2 = 2 * best.cost / max(1, f.size - 4)
    # covariance from the Jacobian (pseudo-inverse: a parameter on its bound has a null column)
    try:
        cov = np.linalg.pinv(best.jac.T @ best.jac, rcond=1e-10) * s2
        se = np.sqrt(np.clip(np.diag(cov), 0, None))
    except np.linalg.LinAlgError:
        se = np.full(4, np.nan)
    fn, zeta = float(best.x[0]), float(best.x[1])
    stops = [f"f_n {bound:g} Hz (the {side} end of the fitted band {band[0]:g}-{band[1]:g} Hz)"
             for bound, side in ((band[0], "lower"), (band[1], "upper"))
             if abs(fn - bound) <= AT_BOUND * bound]
    stops += [f"zeta {bound:g} (the {side} bound)"
              for bound, side in ((ZETA_BOUNDS[0], "lower"), (ZETA_BOUNDS[1], "upper"))
              if abs(zeta - bound) <= AT_BOUND * bound]
    if stops:
        return BodyMode(fn, zeta, math.nan, math.nan, "carma", " and ".join(stops))
    return BodyMode(fn, zeta, float(se[0]), float(se[1]), "carma")


def fit_ar(y: FloatArray, fs: float, band: tuple[float, float] = AR_BAND) -> BodyMode:
    """Body mode as the dominant AR(p) pole pair in ``band`` (see module doc)."""
    y = np.asarray(y, dtype=float) - float(np.mean(y))
    order = AR_ORDER
    q = max(1, int(round(fs / AR_RATE)))
    if q > 1:
        y = decimate(y, q, ftype="fir", zero_phase=True)
    fs2 = fs / q
    sd = float(np.std(y))
    if not sd > 0:
        raise ValueError("constant signal")
    y = y / sd
    n = y.size
    if n < 10 * order:
        raise ValueError(f"{n} samples after decimation, too few for AR({order})")
    X = np.column_stack([y[order - k - 1:n - k - 1] for k in range(order)])
    b = y[order:]
    a, *_ = np.linalg.lstsq(X, b, rcond=None)
    s2 = float(np.var(b - X @ a))
    z = np.roots(np.concatenate([[1.0], -a]))
    best = None
    for zi in z:
        s = np.log(complex(zi)) * fs2
        if s.imag <= 0:
            continue
        fn = abs(s) / (2 * np.pi)
        zeta = -s.real / abs(s)
        if not (band[0] <= fn <= band[1] and 0 < zeta < 1):
            continue
        w = np.exp(-1j * s.imag / fs2 * np.arange(1, order + 1))
        peak = s2 / abs(1 - np.dot(a, w)) ** 2
        if best is None or peak > best[0]:
            best = (peak, fn, zeta)
    if best is None:
        raise ValueError(f"no AR({order}) pole pair in {band[0]}-{band[1]} Hz")
    return BodyMode(float(best[1]), float(best[2]), float("nan"), float("nan"), "ar")


def _stuck_runs(y: FloatArray) -> np.ndarray:
    """Samples of a frozen sensor: runs of at least :data:`STUCK_SAMPLES` identical values,
    with the sample before a run when it is an outlier (an invalid marker).
    """
    out = np.zeros(y.size, dtype=bool)
    if y.size < STUCK_SAMPLES:
        return out
    same = np.concatenate(([False], (np.diff(y) == 0) & np.isfinite(y[1:])))
    edges = np.flatnonzero(np.diff(np.concatenate(([0], same.view(np.int8), [0]))))
    for a, b in zip(edges[::2], edges[1::2]):  # y[a-1] == y[a] == ... == y[b-1]
        if b - a + 1 >= STUCK_SAMPLES:
            out[a - 1:b] = True
    if out.any() and (~out).sum() > 2:
        rest = y[~out & np.isfinite(y)]
        med = float(np.median(rest))
        spread = 1.4826 * float(np.median(np.abs(rest - med))) or float(np.std(rest))
        starts = np.flatnonzero(np.diff(out.view(np.int8)) == 1)  # the sample before a run
        for k in starts:
            if np.isfinite(y[k]) and abs(y[k] - med) > 10 * spread:
                out[k] = True
    return out


def _spans(t: FloatArray, mask: np.ndarray, most: int = 3) -> str:
    """``t 1.3 s, t 2.1-2.5 s and 4 more runs``: the time spans of ``mask``'s runs."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.view(np.int8), [0]))))
    runs = list(zip(edges[::2].tolist(), edges[1::2].tolist()))
    base = float(t[0]) if float(t[0]) > 1e8 else 0.0
    where = "+" if base else ""
    named = [f"t {where}{float(t[a]) - base:.4g} s" if b - a == 1
             else f"t {where}{float(t[a]) - base:.4g}-{float(t[b - 1]) - base:.4g} s"
             for a, b in runs[:most]]
    more = f" and {len(runs) - most} more runs" if len(runs) > most else ""
    return ", ".join(named) + more + (" from the window's start" if base else "")


class OutputOnlyEstimator:
    """Per-window body-mode tracking from one acceleration ``channel`` (``x1_ddot``) by
    ``method`` ``"carma"`` or ``"ar"``.
    """

    name = "output_only"
    own_track = False

    def __init__(self, channel: str, method: str = "carma") -> None:
        if method not in METHODS:
            raise UsageError(f"output-only method {method!r} unknown; expected one of {', '.join(METHODS)}")
        self.channel = channel
        self.method = method
        self.lag = 0.0
        self.overlap = 1.0
        self.windows = 0
        self.skipped = 0
        self.cpu = 0.0
        self.missing = 0
        self._t_done: float | None = None

    def process(self, t: FloatArray, data: Mapping[str, FloatArray]) -> StepResult:
        """Body mode of one window (or a skip with the reason)."""
        c0 = time.process_time()
        y = data.get(self.channel)
        t0, t1 = float(t[0]), float(t[-1])
        if y is None:
            raise InputError(f"output-only mode: the stream has no channel {self.channel!r}; "
                             f"it has {', '.join(data)} (map one with --map {self.channel}=MSG.SIGNAL)")
        y = np.asarray(y, dtype=float)
        warns: list[str] = []
        stuck = _stuck_runs(y)
        if stuck.any():
            y = np.where(stuck, np.nan, y)
            warns.append(f"{int(stuck.sum())} samples of {self.channel} frozen at one value or "
                         f"an invalid marker ({_spans(t, stuck)}): left out as missing")
        ok = np.isfinite(y)
        frac = 1.0 - float(ok.mean())
        # missing samples not in an earlier window: the summary's total counts each once
        new = t > self._t_done if self._t_done is not None else np.ones(t.size, dtype=bool)
        self.missing += int((~ok & new).sum())
        self._t_done = t1 if self._t_done is None else max(self._t_done, t1)

        def skip(reason: str) -> StepResult:
            self.skipped += 1
            self.cpu += time.process_time() - c0
            return StepResult(Skip(t1, t0, self.name, reason))

        if frac > MAX_MISSING or ok.sum() < 16:
            return skip(f"channel {self.channel}: {frac:.0%} of the window's samples missing "
                        f"(> {MAX_MISSING:.0%})" + (f"; {warns[0]}" if warns else ""))
        if frac > 0:
            gaps = ~ok & ~stuck
            y = np.interp(t, t[ok], y[ok])
            if gaps.any():
                warns.append(f"{int(gaps.sum())} missing samples of {self.channel} "
                             f"({_spans(t, gaps)}) bridged by linear interpolation")
        mean = float(np.mean(y))
        if abs(mean) > MAX_MEAN_ACCEL:
            warns.append(f"{self.channel} averages {mean:+.3g} m/s^2 over the window, where a "
                         "body's vertical acceleration averages 0: gravity not removed "
                         "(e.g. --map x1_ddot=MSG.SIGNAL-9.81) or another axis mapped; the mean "
                         "is removed before the fit, an axis other than the vertical is not "
                         "the body mode")
        rms = float(np.std(y))
        if rms < MIN_RMS:
            return skip(f"too little excitation: body acceleration RMS {rms:.3g} m/s^2 < "
                        f"{MIN_RMS:g} m/s^2 (vehicle at rest?)")
        dt = float(np.median(np.diff(t)))
        fs = 1.0 / dt
        nominal = CARMA_BAND if self.method == "carma" else AR_BAND
        top = min(nominal[1], NYQUIST_SHARE * fs / 2)
        if top < MIN_BAND_TOP:
            return skip(f"sample rate {fs:.3g} Hz too low for the body mode: its Nyquist "
                        f"frequency {fs / 2:.3g} Hz leaves a band below {MIN_BAND_TOP:g} Hz")
        if top < nominal[1]:
            warns.append(f"fitted up to {top:.3g} Hz, not {nominal[1]:g} Hz: the stream's "
                         f"{fs:.3g} Hz sample rate has its Nyquist frequency at {fs / 2:.3g} Hz")
        band = (nominal[0], top)
        try:
            mode = (fit_carma(y, fs, band=band) if self.method == "carma"
                    else fit_ar(y, fs, band=band))
        except ValueError as exc:
            return skip(f"no body mode found: {exc}")
        params = {"f_body": mode.f_hz, "zeta_body": mode.zeta}
        se = {"f_body": mode.f_se, "zeta_body": mode.zeta_se}
        if mode.at_bound:
            warns.append(f"the spectral fit stopped at {mode.at_bound}: no body mode inside "
                         "the search; the value is the bound, not an estimate (no standard "
                         "error, not tracked)")
        self.windows += 1
        cpu = time.process_time() - c0
        self.cpu += cpu
        info = {"mode": "output_only", "method": mode.method, "f_hz": mode.f_hz,
                "zeta": mode.zeta, "accel_rms": rms, "cpu_ms": 1e3 * cpu, "warnings": warns}
        event = Estimate(t1, t0, self.name, params, se, info=info)
        if mode.at_bound:
            return StepResult(event)
        # the tracker needs an uncertainty: without one (AR poles), 10 % of the value
        track_se = {k: (v if math.isfinite(v) else 0.1 * params[k]) for k, v in se.items()}
        return StepResult(event, params, track_se)

    def summary(self) -> dict[str, Any]:
        """Windows fitted and skipped, CPU time and the channel's missing samples, each counted once."""
        return {"windows": self.windows, "skipped": self.skipped, "cpu_s": self.cpu,
                "missing_samples": self.missing}


def make_output_only_estimator(spec: Any, channels: list[str], fs: float) -> OutputOnlyEstimator:
    """The output-only estimator of a :class:`~estimator.stream.pipeline.MonitorSpec`."""
    return OutputOnlyEstimator(spec.accel_channel, method=spec.oo_method)
