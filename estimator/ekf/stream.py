"""The EKF as a window estimator for the monitor: same interface and same information as the
sliding window (the fair baseline of ``docs/monitoring.md``).

Each call filters the window's new samples and reports the parameter state at the window end.
"""
from __future__ import annotations

import math
import time
from typing import Any, Mapping, Sequence

import numpy as np

from estimator.ekf.filter import AugmentedEKF, EKFTuning, ParamEKF, window_nis
from estimator.identify import Parameters
from estimator.stream.config import WindowConfig, default_decimation
from estimator.stream.events import Estimate
from estimator.stream.monitor import StepResult
from estimator.stream.wear_streams import DBC_RESOLUTION
from estimator.stream.window import SlidingWindowIdentifier, noise_floor
from suspid.models.base import FloatArray, SuspensionModel
from suspid.simulate import uniform_step


#: a step between two samples with the road longer than this many sample steps is a gap
GAP_STEPS = 1.5
#: holes in the road of up to this many samples between two with it are bridged linearly
BRIDGE_SAMPLES = 2


def noise_sd(y: FloatArray, resolution: float) -> float:
    """White-noise std of ``y``: its noise floor, never below the quantization ``resolution / sqrt(12)``."""
    nf = noise_floor(np.asarray(y, dtype=float))
    return max(nf if math.isfinite(nf) else 0.0, resolution / math.sqrt(12.0))


class WindowEKF:
    """What both window EKFs share: the monitor's estimator interface, counters, the report."""

    name = "ekf"
    #: the filter's state is itself the tracked parameter (alerts use it directly)
    own_track = True
    lag = 0.0
    overlap = 1.0

    def _setup(self, model: SuspensionModel, tuning: EKFTuning, decimate: int) -> None:
        self.model = model
        self.tuning = tuning
        self.decimate = max(1, int(decimate))
        self.t_last = -math.inf
        self._t_seen = -math.inf
        self._phase = 0
        #: nominal sample step of the stream (s), set on the first window
        self.h = math.nan
        self.samples = 0
        self.cpu = 0.0
        #: motion restarts after gaps and the data time they bridged (s)
        self.restarts = 0
        self.gap_s = 0.0
        self.nis_windows_out = 0
        self._nis0 = (0.0, 0)
        self.start_from: dict[str, float] = {}

    def _report(self, t: FloatArray, ekf: ParamEKF, cpu: float, checked: Sequence[str] | None,
                notes: list[str], head: dict[str, Any], tail: dict[str, Any],
                track: bool = True, first: str | None = None) -> StepResult:
        """The window's estimate: parameters, NIS and its band, warnings (``first`` leads)."""
        vals = ekf.param_values()
        se = ekf.param_stderr()
        ok = all(math.isfinite(vals[k]) and vals[k] > 0 for k in (vals if checked is None else checked))
        warns = [] if ok else ["EKF parameter state left the physical range"]
        nis, _, lo, hi, nis_warning = window_nis(ekf.nis_sum, ekf.nis_dof, self._nis0)
        self._nis0 = (ekf.nis_sum, ekf.nis_dof)
        if nis_warning is not None:
            self.nis_windows_out += 1
            warns.append(nis_warning)
        warns += notes
        if first is not None:
            warns.insert(0, first)
        info: dict[str, Any] = {**head, "samples": self.samples, "cpu_ms": 1e3 * cpu,
                                "augmented": list(ekf.aug), "nis": nis, "nis_band": [lo, hi],
                                "warnings": warns, **tail}
        if self.start_from:
            info["start_from_first_window"] = dict(self.start_from)
        ev = Estimate(float(t[-1]), float(t[0]), self.name, vals, se, info=info)
        track = track and ok
        return StepResult(ev, vals if track else None, se if track else None)

    def _summary(self, ekf: ParamEKF | None, head: dict[str, Any], augmented: list[str],
                 held: dict[str, str]) -> dict[str, Any]:
        """Samples filtered, CPU time, consistency, restarts."""
        return {**head, "samples": self.samples, "cpu_s": self.cpu,
                "cpu_us_per_sample": 1e6 * self.cpu / self.samples if self.samples else None,
                "augmented": augmented, "held": held,
                "nis": (ekf.nis_sum / ekf.nis_dof) if ekf is not None and ekf.nis_dof else None,
                "nis_windows_inconsistent": self.nis_windows_out,
                "restarts": self.restarts, "gap_s": self.gap_s}


def ekf_tuning(spec: Any, fs: float) -> tuple[EKFTuning, int]:
    """The EKF's tuning (``ekf.q``) and decimation (``ekf.decimate``, default to about 250 Hz)."""
    tun = EKFTuning() if spec.ekf_q is None else EKFTuning(q_param=spec.ekf_q)
    return tun, spec.ekf_decimate or max(1, int(math.floor(fs / 250.0 + 1e-9)))


class EKFWindowEstimator(WindowEKF):
    """Joint state/parameter EKF fed window by window.

    ``params`` (SI) hold the fixed values and the ``augmented`` ones' starts; ``decimate``: use every
    n-th sample; ``held``: ``parameter -> reason`` of free parameters the filter holds;
    ``first_window`` ``(Parameters, WindowConfig, names)`` starts ``names`` from a sliding-window fit
    of the first window.
    """

    def __init__(self, model: SuspensionModel, params: Mapping[str, float],
                 augmented: Sequence[str], channels: Sequence[str],
                 tuning: EKFTuning | None = None, decimate: int = 1,
                 held: Mapping[str, str] | None = None,
                 first_window: tuple[Parameters, WindowConfig, Sequence[str]] | None = None) -> None:
        self._setup(model, tuning or EKFTuning(), decimate)
        self.held = dict(held or {})
        self.first_window = first_window
        self.params = dict(params)
        self.augmented = list(augmented)
        self.channels = [c for c in model.channels if c in channels]
        self.ekf: AugmentedEKF | None = None
        self._u_prev: FloatArray | None = None
        self.held_note = ""
        self._t_step = -math.inf
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

    def _start(self, t: FloatArray, data: Mapping[str, FloatArray]) -> None:
        if self.first_window is not None:   # the named parameters start from a fit of this window
            params, cfg, names = self.first_window
            res = SlidingWindowIdentifier(self.model, params, cfg, self.channels).process(t, data)
            if res.skipped or not res.identifiable:
                self.held_note = (f"first window not identified ({res.reason or 'unidentifiable'}); "
                                  "the EKF starts from the defaults")
            else:
                for k in names:
                    if k in res.params and k in self.params:
                        self.params[k] = float(res.params[k])
                        self.start_from[k] = float(res.params[k])
        self.h = h = uniform_step(t) or float(np.median(np.diff(t)))
        dt = h * self.decimate
        self.ekf = self._new_filter(dt)
        sig = [max(noise_sd(data[c], DBC_RESOLUTION.get(c, 0.0)), 1e-9) for c in self.channels]
        self.ekf.R = np.diag(np.square(sig))
        if self.tuning.input_noise:
            roads = list(self.model.roads) + [f"{r}_dot" for r in self.model.roads]
            sig_u = np.array([noise_sd(data[c], DBC_RESOLUTION.get(c, 0.0)) if c in data else 0.0
                              for c in roads])
            nr = len(self.model.roads)
            for i, r in enumerate(self.model.roads):
                if f"{r}_dot" not in data:  # the road's central difference (see _road)
                    sig_u[nr + i] = sig_u[i] / (math.sqrt(2.0) * h)
            self.ekf.set_input_noise(sig_u)
            self._sig_u = sig_u
        self.ekf.x[:self.ekf.nx, 0] = self._motion_state(data, 0)

    def _new_filter(self, dt: float) -> AugmentedEKF:
        """A filter at the start values, with the first window's measurement and road noise when known."""
        ekf = AugmentedEKF(self.model, self.params, self.augmented, self.channels, dt, self.tuning)
        if self.ekf is not None:
            ekf.R = self.ekf.R.copy()
            if self._sig_u is not None:
                ekf.set_input_noise(self._sig_u)
        return ekf

    def _recover(self, data: Mapping[str, FloatArray], k: int, t_k: float) -> None:
        """Start the filter over at sample ``k`` (time ``t_k``, s) after its state stopped being finite."""
        old = self._filter()
        ekf = self._new_filter(old.dt)
        ekf.x[:ekf.nx, 0] = self._motion_state(data, k)
        ekf.nis_sum, ekf.nis_dof = ((old.nis_sum, old.nis_dof) if math.isfinite(old.nis_sum)
                                    else self._nis_ok)
        self.ekf = ekf
        self.divergences += 1

    def _motion_state(self, data: Mapping[str, FloatArray], k: int) -> FloatArray:
        """Motion states ``[q, q']`` (m, m/s) from the measurements at sample ``k``; the others at rest."""
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
        """Which of ``n`` samples the filter steps to: those with the road, and short holes between them."""
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
        """Start the motion over at sample ``k`` (time ``t_k``, s) after a gap; returns the warning.

        The parameters keep their estimate, their random walk predicted over the real elapsed time.
        """
        ekf = self._filter()
        elapsed = t_k - self._t_step
        ekf.x[:ekf.nx, 0] = self._motion_state(data, k)
        ekf.restart_motion(ekf.nq, self.tuning, max(elapsed, 0.0))
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
        """Step the filter through the new samples; returns the divergences and the first one's time (s)."""
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
        notes = ([self.held_note] if self.held_note and self.samples == 0 else []) + gaps
        first = None if not diverged else (
            f"EKF diverged {diverged} time{'s' if diverged > 1 else ''} in this window (first at "
            f"t={first_div:.4f} s): its state or covariance was no longer finite; restarted from the "
            "start values and the measurements each time; this estimate goes to neither the tracker "
            "nor the alerts (the model does not describe the data: a sensor offset kept, a wrong "
            "fixed value)")
        tail = {k: v for k, v in (("gaps", len(gaps)), ("divergences", diverged),
                                  ("held", dict(self.held))) if v}
        # a restarted filter's values are no estimate
        return self._report(t, self._filter(), cpu, None, notes, {}, tail, not diverged, first)

    def summary(self) -> dict[str, Any]:
        """Samples filtered, CPU time, consistency, restarts and divergences."""
        return {**self._summary(self.ekf, {}, list(self.augmented), dict(self.held)),
                "divergences": self.divergences}


#: parameter kinds the augmented EKF can carry in its state (affine in the model's matrices)
EKF_KINDS = ("damping", "stiffness")


def ekf_plan(model: SuspensionModel, free: Sequence[str], requested: Sequence[str] | None = None
             ) -> tuple[list[str], dict[str, str]]:
    """Which free parameters the EKF estimates (default: ``requested`` or every free damper and
    spring), and ``parameter -> reason`` of those it holds.
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
    tun, dec = ekf_tuning(spec, fs)
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
