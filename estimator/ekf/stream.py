"""The EKF as a window estimator for the monitor: same interface and same information as the
sliding window.

Every call gets the current window; the filter runs over the samples it has not seen yet
(one predict/update per sample, at the stream's rate divided by ``decimate``) and reports
its parameter state and standard deviations at the window end.

A fair baseline gets what the sliding window gets:

free parameters
    every free damper and spring is in the filter's state (``ekf.params`` narrows it); a
    free parameter the filter cannot estimate (a mass, a length: not affine in its
    matrices) is *held* at its starting value and every estimate says so, with the reason
    (``held``).
starting values
    ``--init`` or ``--nominal`` when given; otherwise the first window's sliding-window
    estimate (a cold Nelder-Mead fit of that window, its CPU counted as the EKF's), so
    neither side starts from a default the other does not use.
measurement noise
    ``R`` from the data's own noise floor on the first window (fourth differences,
    :func:`estimator.stream.window.noise_floor`), never below the DBC quantization; the
    road channels' noise floor, found the same way, enters ``Q`` through the prediction's
    sensitivity to the road (``EKFTuning.input_noise``): the road is an input measured with
    error on both sides (the sliding window fuses its displacement with the integral of its
    velocity above ``WindowConfig.road_fusion_hz``).
gaps in the data
    the sliding window fits every window from a fresh initial state (least squares) and
    skips a window whose time base jumps or whose channels miss more than ``max_missing``,
    so after a gap it starts over with the parameters carried on. The filter does the same
    (:meth:`EKFWindowEstimator._restart`): where the time between two samples with the road
    exceeds ``GAP_STEPS`` sample steps (a jump in the time base, windows without data, or a
    hole in the road longer than ``BRIDGE_SAMPLES`` samples: the motion cannot be predicted
    without its input), it does not bridge the gap with one step of the nominal length nor
    with an interpolated road; the motion states restart from the measurements
    after the gap (as at the first sample, with the initial motion covariance), and the
    parameters are predicted over the real elapsed time (their random walk, ``q_param^2``
    times the gap's length, added to their variance). Each such restart is reported in the
    window's ``gaps`` and ``warnings`` and counted in the summary (``restarts``).
consistency
    the normalised innovation squared (NIS) of every update is summed per window; its mean
    per degree of freedom is ``1`` for a filter whose model and noise fit the data. Each
    estimate reports it (``nis``, with ``nis_band``) and warns when it leaves the chi-square
    99.9 % band of the window widened 1.5 times: the filter no longer fits the data and its
    error bars are not to be trusted.
"""
from __future__ import annotations

import math
import time
from typing import Any, Mapping, Sequence

import numpy as np


from estimator.ekf.filter import AugmentedEKF, EKFTuning, window_nis
from estimator.identify import Parameters
from estimator.stream.config import WindowConfig, default_decimation
from estimator.stream.events import Estimate
from estimator.stream.monitor import StepResult
from estimator.stream.wear_streams import DBC_RESOLUTION
from estimator.stream.window import SlidingWindowIdentifier, noise_floor
from suspid.models.base import FloatArray, SuspensionModel
from suspid.simulate import uniform_step


#: a step between two consecutive samples with the road longer than this many sample steps
#: is a gap in the data: the filter restarts its motion states after it
GAP_STEPS = 1.5
#: holes in the road of up to this many samples between two samples with it are bridged by
#: linear interpolation (4 ms at 500 Hz, under a twentieth of a wheel-hop period: the rule
#: the decimation keeps for the road's first-order hold); longer ones are gaps
BRIDGE_SAMPLES = 2


class EKFWindowEstimator:
    """Joint state/parameter EKF fed window by window.

    Parameters
    ----------
    model : SuspensionModel
    params : mapping
        Every parameter value (SI): fixed ones and the nominal values of ``augmented``.
    augmented : sequence of str
        Parameters the filter estimates (default ``c1, k1``).
    channels : sequence of str
        Measured channels used in the update.
    tuning : EKFTuning, optional
    decimate : int
        Use every ``decimate``-th sample.
    held : dict, optional
        ``parameter -> reason`` of free parameters the filter holds (reported per estimate).
    first_window : tuple, optional
        ``(Parameters, WindowConfig, names)``: start ``names`` from a sliding-window fit of
        the first window instead of ``params``.
    nis_level : float
        Two-sided probability of the NIS band (0.999).
    nis_tolerance : float
        Factor the band is widened by (1.5): the chi-square band assumes white innovations
        and exact noise levels, while ``R`` and ``Q`` are estimated and the samples are
        correlated; a consistent filter stays within 0.85-1.25 per dof on the benchmark
        streams, one holding wrong tyre parameters at 13-25.
    """

    name = "ekf"
    #: the filter's state is itself the tracked parameter (alerts use it directly)
    own_track = True
    lag = 0.0
    overlap = 1.0

    def __init__(self, model: SuspensionModel, params: Mapping[str, float],
                 augmented: Sequence[str], channels: Sequence[str],
                 tuning: EKFTuning | None = None, decimate: int = 1,
                 held: Mapping[str, str] | None = None,
                 first_window: tuple[Parameters, WindowConfig, Sequence[str]] | None = None,
                 nis_level: float = 0.999, nis_tolerance: float = 1.5) -> None:
        self.model = model
        self.held = dict(held or {})
        self.first_window = first_window
        self.nis_level = nis_level
        self.nis_tolerance = nis_tolerance
        self.start_from: dict[str, float] = {}
        self.nis_windows_out = 0
        self._nis0 = (0.0, 0)
        self.params = dict(params)
        self.augmented = list(augmented)
        self.channels = [c for c in model.channels if c in channels]
        self.tuning = tuning or EKFTuning()
        self.decimate = max(1, int(decimate))
        self.ekf: AugmentedEKF | None = None
        self.t_last = -math.inf
        self.samples = 0
        self.cpu = 0.0
        self._u_prev: FloatArray | None = None
        self._phase = 0
        self.held_note = ""
        #: nominal sample step of the stream (s), set on the first window
        self.h = math.nan
        #: data time of the last sample with the road (s) and of the last filtered one
        self._t_seen = -math.inf
        self._t_step = -math.inf
        #: motion restarts after gaps, and the data time they bridged (s)
        self.restarts = 0
        self.gap_s = 0.0
        #: restarts after the filter diverged (:meth:`_recover`)
        self.divergences = 0
        self._nis_ok: tuple[float, int] = (0.0, 0)
        self._sig_u: FloatArray | None = None

    def _road(self, data: Mapping[str, FloatArray], t: FloatArray) -> FloatArray:
        n = t.size
        nr = len(self.model.roads)
        U = np.zeros((n, 2 * nr))
        for i, r in enumerate(self.model.roads):
            v = data.get(r)
            if v is None:
                continue
            v = np.asarray(v, dtype=float)
            ok = np.isfinite(v)
            if ok.sum() >= 2 and not ok.all():
                v = np.interp(t, t[ok], v[ok])
            elif not ok.any():
                continue
            U[:, i] = v
            vd = data.get(f"{r}_dot")
            if vd is not None and np.all(np.isfinite(vd)):
                U[:, nr + i] = vd
            else:
                U[:, nr + i] = np.gradient(v, t) if n > 2 else 0.0
        return U

    def _first_window_start(self, t: FloatArray, data: Mapping[str, FloatArray]) -> None:
        """Start the parameters named in ``first_window`` from a fit of this window."""
        if self.first_window is None:
            return
        params, cfg, names = self.first_window
        ident = SlidingWindowIdentifier(self.model, params, cfg, self.channels)
        res = ident.process(t, data)
        if res.skipped or not res.identifiable:
            self.held_note = (f"first window not identified ({res.reason or 'unidentifiable'}); "
                              "the EKF starts from the defaults")
            return
        for k in names:
            if k in res.params and k in self.params:
                self.params[k] = float(res.params[k])
                self.start_from[k] = float(res.params[k])

    def _start(self, t: FloatArray, data: Mapping[str, FloatArray]) -> None:
        self._first_window_start(t, data)
        h = uniform_step(t) or float(np.median(np.diff(t)))
        dt = h * self.decimate
        self.ekf = self._new_filter(dt)
        sig = []
        for c in self.channels:
            nf = noise_floor(np.asarray(data[c], dtype=float))
            q = DBC_RESOLUTION.get(c, 0.0) / math.sqrt(12.0)
            s = max(nf if math.isfinite(nf) else 0.0, q, 1e-9)
            sig.append(s)
        self.ekf.R = np.diag(np.square(sig))
        if self.tuning.input_noise:
            roads = list(self.model.roads) + [f"{r}_dot" for r in self.model.roads]
            sig_u = np.zeros(len(roads))
            for i, c in enumerate(roads):
                if c in data:
                    nf = noise_floor(np.asarray(data[c], dtype=float))
                    q = DBC_RESOLUTION.get(c, 0.0) / math.sqrt(12.0)
                    sig_u[i] = max(nf if math.isfinite(nf) else 0.0, q)
            nr = len(self.model.roads)
            for i, r in enumerate(self.model.roads):
                if f"{r}_dot" not in data:  # the road's central difference (see _road)
                    sig_u[nr + i] = sig_u[i] / (math.sqrt(2.0) * h)
            self.ekf.set_input_noise(sig_u)
            self._sig_u = sig_u
        self.h = h
        self.ekf.x[:self.ekf.nx, 0] = self._motion_state(data, 0)

    def _new_filter(self, dt: float) -> AugmentedEKF:
        """A filter at the start values (motion at rest, the initial covariance), with the
        measurement and road noise of the first window when they are known."""
        ekf = AugmentedEKF(self.model, self.params, self.augmented, self.channels, dt,
                           self.tuning)
        if self.ekf is not None:
            ekf.R = self.ekf.R.copy()
            if self._sig_u is not None:
                ekf.set_input_noise(self._sig_u)
        return ekf

    def _recover(self, data: Mapping[str, FloatArray], k: int, t_k: float) -> None:
        """Start the filter over at sample ``k`` (time ``t_k``, s) after it diverged.

        A state or covariance that is no longer finite (a model far from the data: a sensor
        offset kept, a wrong fixed value) makes every later update fail; the filter starts
        over from the start values and the measurements at ``k``, its consistency sums kept.
        Counted per window (:meth:`process`) and in the summary (``divergences``).
        """
        old = self._filter()
        ekf = self._new_filter(old.dt)
        ekf.x[:ekf.nx, 0] = self._motion_state(data, k)
        ekf.nis_sum, ekf.nis_dof = ((old.nis_sum, old.nis_dof) if math.isfinite(old.nis_sum)
                                    else self._nis_ok)
        self.ekf = ekf
        self.divergences += 1

    def _motion_state(self, data: Mapping[str, FloatArray], k: int) -> FloatArray:
        """Motion states ``[q, q']`` from the measurements at sample ``k`` of ``data``.

        A measured coordinate gives its position, its ``_dot`` channel (or the central
        difference of the next samples) its velocity; the others start at rest (m, m/s).
        """
        nq = len(self.model.coords)
        z = np.zeros(2 * nq)
        h = self.h
        for i, c in enumerate(self.model.coords):
            if c in data:
                y = np.asarray(data[c], dtype=float)[k:k + 3]
                if y.size and np.isfinite(y[0]):
                    z[i] = y[0]
                if y.size > 2 and np.all(np.isfinite(y)):
                    z[nq + i] = (y[2] - y[0]) / (2 * h)
            v = data.get(f"{c}_dot")
            if v is not None and k < len(v) and np.isfinite(v[k]):
                z[nq + i] = float(v[k])
        return z

    def _usable(self, data: Mapping[str, FloatArray], n: int) -> np.ndarray:
        """Which of ``n`` samples the filter steps to: those with every road channel, and
        holes of at most ``BRIDGE_SAMPLES`` samples between two of them (their road
        interpolated linearly, :meth:`_road`). A longer hole, or one at either end of the
        samples, is left out: the next sample after it restarts the motion (:meth:`_restart`).
        """
        ok = np.ones(n, dtype=bool)
        for r in self.model.roads:
            if r in data:
                ok &= np.isfinite(data[r])
        if ok.all():
            return ok
        out = ok.copy()
        miss = np.flatnonzero(~ok)
        starts = miss[np.r_[True, np.diff(miss) > 1]]
        ends = miss[np.r_[np.diff(miss) > 1, True]] + 1
        for a, b in zip(starts.tolist(), ends.tolist()):
            if a > 0 and b < n and b - a <= BRIDGE_SAMPLES:
                out[a:b] = True
        return out

    def _restart(self, data: Mapping[str, FloatArray], k: int, t_k: float) -> str:
        """Start the motion over at sample ``k`` (time ``t_k``, s) after a gap in the data.

        The motion states come from the measurements at ``k`` (:meth:`_motion_state`) with
        the initial motion covariance and no correlation with the parameters; the parameters
        keep their estimate and covariance, their random walk predicted over the real time
        elapsed since the last filtered sample. Returns the warning that reports it.
        """
        ekf = self._filter()
        nx = ekf.nx
        tu = self.tuning
        elapsed = t_k - self._t_step
        ekf.x[:nx, 0] = self._motion_state(data, k)
        P = ekf.P.copy()
        P[:nx, :] = 0.0
        P[:, :nx] = 0.0
        nq = ekf.nq
        P[:nx, :nx] = np.diag([tu.p0_pos ** 2] * nq + [tu.p0_vel ** 2] * nq)
        P[nx:, nx:] += np.eye(P.shape[0] - nx) * tu.q_param ** 2 * max(elapsed, 0.0)
        ekf.P = P
        gap = t_k - self._t_seen
        self.restarts += 1
        self.gap_s += gap
        return (f"gap in the data: no sample with the road from t={self._t_seen:.4f} s to "
                f"t={t_k:.4f} s ({gap:.4g} s); the EKF's motion state restarted from the "
                f"measurements after it, its parameters predicted over the {elapsed:.4g} s elapsed")

    def _filter(self) -> AugmentedEKF:
        if self.ekf is None:
            raise RuntimeError("the EKF starts with the first window")
        return self.ekf

    def _run(self, tn: FloatArray, U: FloatArray, Y: FloatArray,
             dnew: Mapping[str, FloatArray], usable: np.ndarray, gaps: list[str]
             ) -> tuple[int, float]:
        """Step the filter through the new samples (times ``tn``, road ``U``, measurements
        ``Y``); gaps are appended to ``gaps``. Returns the divergences (:meth:`_recover`) and
        the time of the first (s; NaN without one)."""
        ekf = self._filter()
        step = ekf.step
        limit = GAP_STEPS * self.h
        diverged = 0
        first_div = math.nan
        for k in range(tn.size):
            if not usable[k]:      # no input: nothing to predict the motion with
                continue
            tk = float(tn[k])
            gap = self._u_prev is not None and tk - self._t_seen > limit
            if gap:
                gaps.append(self._restart(dnew, k, tk))
            self._t_seen = tk
            if self._u_prev is None or gap:   # the anchor of the following steps
                self._u_prev = U[k]
                self._t_step = tk
                self._phase = 0
                continue
            self._phase = (self._phase + 1) % self.decimate
            if self._phase != 0:
                continue
            try:
                step(Y[k], self._u_prev, U[k])
                failed = not math.isfinite(ekf.nis_sum)
            except (np.linalg.LinAlgError, FloatingPointError, ValueError):
                failed = True
            if failed:
                if not diverged:
                    first_div = tk
                diverged += 1
                self._recover(dnew, k, tk)
                ekf = self._filter()
                step = ekf.step
            else:
                self._nis_ok = (ekf.nis_sum, ekf.nis_dof)
            self._u_prev = U[k]
            self._t_step = tk
            self.samples += 1
        return diverged, first_div

    def process(self, t: FloatArray, data: Mapping[str, FloatArray]) -> StepResult:
        """Filter the window's new samples; report the parameters at the window end."""
        c0 = time.process_time()
        new = t > self.t_last + 1e-12
        if self.ekf is None:
            self._start(t, data)
        tn = t[new]
        diverged = 0
        first_div = math.nan
        gaps: list[str] = []
        if tn.size:
            U = self._road(data, t)[new]
            Y = np.column_stack([np.asarray(data[c], dtype=float)[new] if c in data
                                 else np.full(tn.size, np.nan) for c in self.channels])
            dnew = {c: np.asarray(v, dtype=float)[new] for c, v in data.items()}
            usable = self._usable(dnew, tn.size)
            err = np.seterr(over="ignore", invalid="ignore")   # a divergence is said below
            try:
                diverged, first_div = self._run(tn, U, Y, dnew, usable, gaps)
            finally:
                np.seterr(**err)
            self.t_last = float(tn[-1])
        cpu = time.process_time() - c0
        self.cpu += cpu
        ekf = self._filter()
        vals = ekf.param_values()
        se = ekf.param_stderr()
        ok = all(math.isfinite(v) and v > 0 for v in vals.values())
        warns = [] if ok else ["EKF parameter state left the physical range"]
        nis, dof, lo, hi, nis_warning = window_nis(ekf.nis_sum, ekf.nis_dof, self._nis0,
                                                   self.nis_level, self.nis_tolerance)
        self._nis0 = (ekf.nis_sum, ekf.nis_dof)
        if nis_warning is not None:
            self.nis_windows_out += 1
            warns.append(nis_warning)
        if self.held_note and self.samples == 0:
            warns.append(self.held_note)
        warns.extend(gaps)
        if diverged:
            warns.insert(0, f"EKF diverged {diverged} time{'s' if diverged > 1 else ''} in this "
                            f"window (first at t={first_div:.4f} s): its state or covariance "
                            "was no longer finite; restarted from the start values and the "
                            "measurements each time; this estimate goes to neither the "
                            "tracker nor the alerts (the model does not describe the data: a "
                            "sensor offset kept, a wrong fixed value)")
        info: dict[str, Any] = {"samples": self.samples, "cpu_ms": 1e3 * cpu,
                                "augmented": list(self.augmented),
                                "nis": nis, "nis_band": [lo, hi], "warnings": warns}
        if gaps:
            info["gaps"] = len(gaps)
        if diverged:
            info["divergences"] = diverged
        if self.held:
            info["held"] = dict(self.held)
        if self.start_from:
            info["start_from_first_window"] = dict(self.start_from)
        ev = Estimate(float(t[-1]), float(t[0]), self.name, vals, se, info=info)
        track = ok and not diverged        # a restarted filter's values are no estimate
        return StepResult(ev, vals if track else None, se if track else None)

    def summary(self) -> dict[str, Any]:
        """Samples filtered and CPU time."""
        ekf = self.ekf
        return {"samples": self.samples, "cpu_s": self.cpu,
                "cpu_us_per_sample": 1e6 * self.cpu / self.samples if self.samples else None,
                "augmented": list(self.augmented), "held": dict(self.held),
                "nis": (ekf.nis_sum / ekf.nis_dof) if ekf is not None and ekf.nis_dof else None,
                "nis_windows_inconsistent": self.nis_windows_out,
                "restarts": self.restarts, "gap_s": self.gap_s, "divergences": self.divergences}


#: parameter kinds the augmented EKF can carry in its state (affine in the model's matrices)
EKF_KINDS = ("damping", "stiffness")


def ekf_plan(model: SuspensionModel, free: Sequence[str], requested: Sequence[str] | None = None
             ) -> tuple[list[str], dict[str, str]]:
    """Which free parameters the EKF estimates, and which it holds with the reason.

    Parameters
    ----------
    model : SuspensionModel
    free : sequence of str
        The free parameters (the sliding window estimates all of them).
    requested : sequence of str, optional
        ``ekf.params``; default every free damper and spring.

    Returns
    -------
    augmented : list of str
    held : dict
        ``parameter -> reason`` for every free parameter left out.
    """
    held: dict[str, str] = {}
    aug: list[str] = []
    for k in free:
        kind = model.spec(k).kind
        if kind not in EKF_KINDS:
            held[k] = (f"a {kind} is not affine in the model's matrices, so the augmented EKF "
                       "cannot carry it in its state; held at its starting value")
        elif requested is not None and k not in requested:
            held[k] = "left out by ekf.params; held at its starting value"
        else:
            aug.append(k)
    return aug, held


def make_ekf_estimator(spec: Any, channels: list[str], fs: float) -> EKFWindowEstimator:
    """The fair EKF of a :class:`~estimator.stream.pipeline.MonitorSpec` (module docstring)."""
    model = spec.model
    aug, held = ekf_plan(model, spec.params.free, spec.ekf_params)
    tun = EKFTuning()
    if spec.ekf_q is not None:
        tun.q_param = spec.ekf_q
    dec = spec.ekf_decimate or max(1, int(math.floor(fs / 250.0 + 1e-9)))
    meas = [c for c in channels if c in model.channels]
    unknown = [k for k in spec.params.free if k not in spec.start_given]
    first = None
    if unknown:
        cfg = WindowConfig(**vars(spec.config))
        if not spec.decimate_given:
            cfg.decimate = default_decimation(model, spec.params.valuesdict(), fs)
        first = (spec.params, cfg, unknown)
    return EKFWindowEstimator(model, spec.params.valuesdict(), aug, meas, tun, decimate=dec,
                              held=held, first_window=first)
