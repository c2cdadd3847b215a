"""The EKF as a window estimator for the monitor: same interface as the Nelder-Mead one.

Every call gets the current window; the filter runs over the samples it has not seen yet
(one predict/update per sample, at the stream's rate divided by ``decimate``) and reports
its parameter state and standard deviations at the window end.
"""
from __future__ import annotations

import math
import time
from typing import Any, Mapping, Sequence

import numpy as np

from estimator.ekf.filter import AugmentedEKF, EKFTuning
from estimator.stream.monitor import StepResult
from estimator.stream.scenarios import DBC_RESOLUTION
from estimator.stream.window import noise_floor
from suspid.models.base import FloatArray, SuspensionModel
from suspid.simulate import uniform_step


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
    """

    name = "ekf"

    def __init__(self, model: SuspensionModel, params: Mapping[str, float],
                 augmented: Sequence[str], channels: Sequence[str],
                 tuning: EKFTuning | None = None, decimate: int = 1) -> None:
        self.model = model
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
        h = uniform_step(t) or float(np.median(np.diff(t)))
        dt = h * self.decimate
        self.ekf = AugmentedEKF(self.model, self.params, self.augmented, self.channels, dt,
                                self.tuning)
        sig = []
        for c in self.channels:
            nf = noise_floor(np.asarray(data[c], dtype=float))
            q = DBC_RESOLUTION.get(c, 0.0) / math.sqrt(12.0)
            s = max(nf if math.isfinite(nf) else 0.0, q, 1e-9)
            sig.append(s)
        self.ekf.R = np.diag(np.square(sig))
        nq = len(self.model.coords)
        z = self.ekf.x[:, 0].copy()
        for i, c in enumerate(self.model.coords):
            if c in data:
                y = np.asarray(data[c], dtype=float)
                if np.isfinite(y[0]):
                    z[i] = y[0]
                if y.size > 2 and np.all(np.isfinite(y[:3])):
                    z[nq + i] = (y[2] - y[0]) / (2 * h)
            if f"{c}_dot" in data and np.isfinite(data[f"{c}_dot"][0]):
                z[nq + i] = data[f"{c}_dot"][0]
        self.ekf.x = z[:, None]

    def _filter(self) -> AugmentedEKF:
        if self.ekf is None:
            raise RuntimeError("the EKF starts with the first window")
        return self.ekf

    def process(self, t: FloatArray, data: Mapping[str, FloatArray]) -> StepResult:
        """Filter the window's new samples; report the parameters at the window end."""
        c0 = time.process_time()
        new = t > self.t_last + 1e-12
        if self.ekf is None:
            self._start(t, data)
        tn = t[new]
        if tn.size:
            U = self._road(data, t)[new]
            Y = np.column_stack([np.asarray(data[c], dtype=float)[new] if c in data
                                 else np.full(tn.size, np.nan) for c in self.channels])
            ekf = self._filter()
            step = ekf.step
            for k in range(tn.size):
                self._phase = (self._phase + 1) % self.decimate
                if self._phase != 0 and self._u_prev is not None:
                    continue
                if self._u_prev is None:
                    self._u_prev = U[k]
                    continue
                step(Y[k], self._u_prev, U[k])
                self._u_prev = U[k]
                self.samples += 1
            self.t_last = float(tn[-1])
        cpu = time.process_time() - c0
        self.cpu += cpu
        ekf = self._filter()
        vals = ekf.param_values()
        se = ekf.param_stderr()
        ok = all(math.isfinite(v) and v > 0 for v in vals.values())
        line = {"type": "estimate", "t": float(t[-1]), "t_start": float(t[0]), "baseline": self.name,
                "params": vals, "stderr": se, "samples": self.samples, "cpu_ms": 1e3 * cpu,
                "warnings": [] if ok else ["EKF parameter state left the physical range"]}
        return StepResult(line, vals if ok else None, se if ok else None)

    def summary(self) -> dict[str, Any]:
        """Samples filtered and CPU time."""
        return {"samples": self.samples, "cpu_s": self.cpu,
                "cpu_us_per_sample": 1e6 * self.cpu / self.samples if self.samples else None}
