"""The EKF baseline with the road unknown: the body equations, filtered sample by sample.

The information and equations of the road-unknown sliding window: the state is every strut's
extension and rate, one zero offset per body acceleration and the free struts' relative dampers
and springs; the body accelerations ``-M_b^-1 G (c o d' + k o d) + b`` are the measurement.
No tyre or wheel parameter is needed. Start, NIS and gaps as the road-measured EKF.
"""
from __future__ import annotations

import math
import time
from typing import Any, Mapping, Sequence

import numpy as np

from estimator.ekf.filter import EKFTuning, ParamEKF
from estimator.ekf.stream import WindowEKF, ekf_tuning, noise_sd
from estimator.identify import Parameters
from estimator.identify.roadfree import fit_road_unknown
from estimator.stream.monitor import StepResult
from estimator.stream.wear_streams import channel_resolution
from suspid.errors import InputError
from suspid.io.csvio import Measurement
from suspid.models.base import FloatArray, SuspensionModel
from suspid.simulate import uniform_step

#: random walk of the body accelerations' zero offsets (m/s^2 per sqrt(s))
Q_OFFSET = 1e-3
#: initial standard deviation of the zero offsets (m/s^2)
P0_OFFSET = 1.0
#: a step longer than this many sample steps is a gap: the deflection states restart
GAP_STEPS = 1.5


class BodyEquationEKF(ParamEKF):
    """filterpy EKF on the body equations: deflections and their rates, offsets, struts.

    ``params`` (SI) hold the ``augmented`` struts' start values; ``channels`` are the body
    accelerations, ride heights and their rates; ``dt`` the step (s); ``accel_var`` each strut's
    deflection-acceleration variance ((m/s^2)^2). InputError when a strut's ride height or every
    body acceleration is missing.
    """

    def __init__(self, model: SuspensionModel, params: Mapping[str, float],
                 augmented: Sequence[str], channels: Sequence[str], dt: float,
                 tuning: EKFTuning, accel_var: FloatArray) -> None:
        p = dict(model.defaults(), **dict(params))
        self.model = model
        self.params = p
        self.tuning = tuning
        self.dt = float(dt)
        sites = model.strut_sites(p)
        heights = model.ride_heights
        missing = [h for h in heights if h not in channels]
        if missing:
            raise InputError(f"road unknown: the EKF needs every strut's ride height; the stream "
                             f"lacks {', '.join(missing)} (channels: {', '.join(channels)})")
        rows = [j for j in model.body_rows(p) if f"{model.coords[j]}_ddot" in channels]
        if not rows:
            raise InputError(f"road unknown: the EKF needs a body acceleration "
                             f"({', '.join(model.coords[j] + '_ddot' for j in model.body_rows(p))}); "
                             f"the stream has {', '.join(channels)}")
        ns, nb = len(sites), len(rows)
        M = model.matrices(p)[0]
        #: body accelerations = -W (c o d' + k o d) + b, W = M_bb^-1 G_b
        G = np.array([[float(s.g[j]) for s in sites] for j in rows])
        self.W = np.linalg.solve(M[np.ix_(rows, rows)], G)
        self.aug = list(augmented)
        self.c_idx = {s.c_name: i for i, s in enumerate(sites) if s.c_name}
        self.k_idx = {s.k_name: i for i, s in enumerate(sites) if s.k_name}
        self.nominal = np.array([float(p[k]) for k in self.aug])
        #: the struts' held dampers and springs (SI)
        self._c0, self._k0 = np.zeros(ns), np.zeros(ns)
        self._c0[list(self.c_idx.values())] = [p[n] for n in self.c_idx]
        self._k0[list(self.k_idx.values())] = [p[n] for n in self.k_idx]
        self.ns, self.nb = ns, nb
        self.nx = 2 * ns + nb
        nz = self.nx + len(self.aug)
        self.channels = ([f"{model.coords[j]}_ddot" for j in rows] + list(heights)
                         + [f"{h}_dot" for h in heights if f"{h}_dot" in channels])
        super().__init__(dim_x=nz, dim_z=len(self.channels))
        h = self.dt
        F = np.eye(nz)
        F[:ns, ns:2 * ns] = h * np.eye(ns)
        self.F = F
        Q = np.zeros((nz, nz))
        a = np.asarray(accel_var, dtype=float)
        Q[:ns, :ns] = np.diag(a * h ** 4 / 4.0)
        Q[:ns, ns:2 * ns] = Q[ns:2 * ns, :ns] = np.diag(a * h ** 3 / 2.0)
        Q[ns:2 * ns, ns:2 * ns] = np.diag(a * h ** 2)
        Q[2 * ns:self.nx, 2 * ns:self.nx] = np.eye(nb) * Q_OFFSET ** 2 * h
        Q[self.nx:, self.nx:] = np.eye(len(self.aug)) * tuning.q_param ** 2 * h
        self.Q = Q
        self.P = np.diag([tuning.p0_pos ** 2] * ns + [tuning.p0_vel ** 2] * ns
                         + [P0_OFFSET ** 2] * nb + [tuning.p0_param ** 2] * len(self.aug))
        self.x = np.concatenate([np.zeros(self.nx), np.ones(len(self.aug))])[:, None]
        self._I = np.eye(nz)
        H0 = np.zeros((len(self.channels), nz))
        for r, c in enumerate(self.channels[nb:], start=nb):
            base = c.removesuffix("_dot")
            i = heights.index(base)
            H0[r, i if c == base else ns + i] = 1.0
        for r in range(nb):
            H0[r, 2 * ns + r] = 1.0
        self._H0 = H0

    def struts(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Every strut's damper and spring (SI) at state ``z``."""
        c, k = self._c0.copy(), self._k0.copy()
        for j, name in enumerate(self.aug):
            v = self.nominal[j] * z[self.nx + j]
            if name in self.c_idx:
                c[self.c_idx[name]] = v
            else:
                k[self.k_idx[name]] = v
        return c, k

    def hx_jac(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Predicted measurement at state ``z`` and its Jacobian."""
        ns, nb = self.ns, self.nb
        d, v = z[:ns], z[ns:2 * ns]
        c, k = self.struts(z)
        H = self._H0.copy()
        y = H @ z
        y[:nb] += -self.W @ (c * v + k * d)
        H[:nb, :ns] = -self.W * k[None, :]
        H[:nb, ns:2 * ns] = -self.W * c[None, :]
        for j, name in enumerate(self.aug):
            if name in self.c_idx:
                i = self.c_idx[name]
                H[:nb, self.nx + j] = -self.W[:, i] * self.nominal[j] * v[i]
            else:
                i = self.k_idx[name]
                H[:nb, self.nx + j] = -self.W[:, i] * self.nominal[j] * d[i]
        return y, H

    def step(self, y: FloatArray) -> None:
        """Predict one step and update with ``y`` (NaN entries left out; Joseph form)."""
        self.x = self.F @ self.x
        self.P = self.F @ self.P @ self.F.T + self.Q
        self.joseph_update(y, lambda: self.hx_jac(self.x[:, 0]))


class RoadFreeEKFEstimator(WindowEKF):
    """The body-equation EKF fed window by window (module docstring).

    ``params`` hold the held values and the free parameters' starts (SI); ``first_window`` the free
    parameters started from the first window's road-unknown fit; the rest as
    :class:`estimator.ekf.stream.EKFWindowEstimator`.
    """

    road = "unknown"

    def __init__(self, model: SuspensionModel, params: Parameters, channels: Sequence[str],
                 tuning: EKFTuning, decimate: int = 1, first_window: Sequence[str] = ()) -> None:
        self._setup(model, tuning, decimate)
        self.params = params.copy()
        self.channels = list(channels)
        self.first_window = list(first_window)
        self.ekf: BodyEquationEKF | None = None
        self.note = ""

    def _start(self, t: FloatArray, data: Mapping[str, FloatArray]) -> BodyEquationEKF:
        model = self.model
        if self.first_window:
            meas = Measurement(np.asarray(t, dtype=float), {},
                               {c: np.asarray(v, dtype=float) for c, v in data.items()
                                if c not in model.input_names}, source="window")
            res = fit_road_unknown(model, meas, self.params, misfit_fails=False)
            for k in self.first_window:
                if k in res.stderr:
                    self.params[k].value = float(res.params[k])
                    self.start_from[k] = float(res.params[k])
                else:
                    self.note = (f"first window did not determine {k}; the EKF starts it from "
                                 f"{self.params[k].value:g} {model.spec(k).unit}")
        self.h = h = uniform_step(t) or float(np.median(np.diff(t)))
        dt = h * self.decimate
        res_q = channel_resolution(model.name)
        # deflection acceleration variance at the filter's step, less the noise part
        acc_var = []
        for name in model.ride_heights:
            dv = np.asarray(data.get(name, np.zeros(0)), dtype=float)[::self.decimate]
            dv = dv[np.isfinite(dv)]
            if dv.size < 10:
                acc_var.append(1.0)
                continue
            a = np.diff(dv, 2) / dt ** 2
            s = noise_sd(data[name], res_q.get(name, 0.0))
            acc_var.append(max(float(np.var(a)) - 6.0 * s * s / dt ** 4, 0.1 * float(np.var(a)),
                               1e-6))
        ekf = BodyEquationEKF(model, self.params.valuesdict(), list(self.params.free), self.channels, dt,
                              self.tuning, np.array(acc_var))
        sig = [max(noise_sd(data[c], res_q.get(c, 0.0)), 1e-9) for c in ekf.channels]
        ekf.R = np.diag(np.square(sig))
        self._init_motion(ekf, data, 0)
        return ekf

    def _init_motion(self, ekf: BodyEquationEKF, data: Mapping[str, FloatArray], k: int,
                     walk: float = 0.0) -> None:
        """Deflections and rates from the ride heights at sample ``k``, covariance :meth:`restart_motion`."""
        ns = ekf.ns
        for i, name in enumerate(self.model.ride_heights):
            y = np.asarray(data[name], dtype=float)[k:k + 3]
            if y.size and np.isfinite(y[0]):
                ekf.x[i, 0] = y[0]
            if y.size > 2 and np.all(np.isfinite(y)):
                ekf.x[ns + i, 0] = (y[2] - y[0]) / (2 * self.h)
            v = data.get(f"{name}_dot")
            if v is not None and k < len(v) and np.isfinite(v[k]):
                ekf.x[ns + i, 0] = float(v[k])
        ekf.restart_motion(ns, self.tuning, walk)

    def process(self, t: FloatArray, data: Mapping[str, FloatArray]) -> StepResult:
        """Filter the window's new samples; report the struts at the window end."""
        c0 = time.process_time()
        if self.ekf is None:
            self.ekf = self._start(t, data)
        ekf = self.ekf
        new = t > self.t_last + 1e-12
        tn = t[new]
        gaps: list[str] = []
        if tn.size:
            Y = np.column_stack([np.asarray(data[c], dtype=float)[new] if c in data
                                 else np.full(tn.size, np.nan) for c in ekf.channels])
            dnew = {c: np.asarray(data[c], dtype=float)[new] for c in self.model.ride_height_channels
                    if c in data}
            limit = GAP_STEPS * self.h
            first = self.samples == 0 and self._t_seen == -math.inf
            for k in range(tn.size):
                tk = float(tn[k])
                if first:
                    first = False
                    self._t_seen = tk
                    continue
                if tk - self._t_seen > limit:
                    gap = tk - self._t_seen
                    self._init_motion(ekf, dnew, k, gap)
                    self.restarts += 1
                    self.gap_s += gap
                    gaps.append(f"gap in the data from t={self._t_seen:.4f} s to t={tk:.4f} s "
                                f"({gap:.4g} s): the EKF's deflection states restarted from the "
                                "ride heights after it")
                    self._t_seen = tk
                    self._phase = 0
                    continue
                self._t_seen = tk
                self._phase = (self._phase + 1) % self.decimate
                if self._phase:
                    continue
                ekf.step(Y[k])
                self.samples += 1
            self.t_last = float(tn[-1])
        cpu = time.process_time() - c0
        self.cpu += cpu
        notes = ([self.note] if self.note else []) + gaps
        self.note = ""
        return self._report(t, ekf, cpu, ekf.aug, notes, {"road": "unknown"},
                            {"gaps": len(gaps)} if gaps else {})

    def summary(self) -> dict[str, Any]:
        """Samples filtered, CPU time, consistency, restarts."""
        ekf = self.ekf
        return self._summary(ekf, {"road": "unknown"}, list(ekf.aug) if ekf is not None else [], {})


def make_roadfree_ekf_estimator(spec: Any, channels: list[str], fs: float) -> RoadFreeEKFEstimator:
    """The road-unknown EKF of a :class:`~estimator.stream.pipeline.MonitorSpec`."""
    params = spec.params.copy()
    if spec.ekf_params:
        for k in params.free:
            if k not in spec.ekf_params:
                params[k].vary = False
    tun, dec = ekf_tuning(spec, fs)
    unknown = [k for k in params.free if k not in spec.start_given]
    return RoadFreeEKFEstimator(spec.model, params, channels, tun, decimate=dec,
                                first_window=unknown)
