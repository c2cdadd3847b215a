"""The sliding window with the road unknown: each window's body equations, fitted linearly
(:func:`estimator.identify.roadfree.fit_road_unknown`, as ``suspid identify --road unknown``).

An estimate describes the window's middle; the linear drift does not apply. The fit's band
starts at ``3 / T`` Hz, which :func:`road_unknown_window` keeps below the body mode.
"""
from __future__ import annotations

import math
import time
from typing import Any, Mapping

import numpy as np

from estimator.identify import Parameters
from estimator.identify.roadfree import FIRST_BIN, body_equations, fit_road_unknown
from estimator.inspection import quarter_car_problem
from estimator.stream.config import WindowConfig
from estimator.stream.events import Estimate, Skip
from estimator.stream.monitor import StepResult, add_inspection
from suspid.errors import InputError
from suspid.io.csvio import Measurement
from suspid.models.base import FloatArray, SuspensionModel
from suspid.models.modes import modes

#: the band's lowest frequency ``3 / T`` lies at most this fraction of the body mode's
BAND_START_OF_BODY_MODE = 0.8


def road_unknown_window(model: SuspensionModel, params: Mapping[str, float]) -> float:
    """Shortest window (s) whose band starts below the body mode at nominal ``params`` (SI):
    ``3 / T`` at most :data:`BAND_START_OF_BODY_MODE` times the slowest natural frequency,
    rounded up to 0.5 s; 0 without an oscillating mode."""
    ms = modes(model, dict(model.defaults(), **dict(params)))
    if not ms:
        return 0.0
    return math.ceil(FIRST_BIN / (BAND_START_OF_BODY_MODE * ms[0].f_n) * 2.0) / 2.0


def road_unknown_params(model: SuspensionModel, params: Parameters
                        ) -> tuple[Parameters, list[str]]:
    """The free parameters a road-unknown monitor can follow, the others held.

    A free parameter outside the body equations (a wheel mass, a tyre) is held at its value;
    when every parameter of the body equations is free (only ratios determined) the first
    mass is held. Returns a copy of ``params`` and one warning per change.
    """
    out = params.copy()
    values = out.valuesdict()
    # every channel the body equations may use: motion channels, ride heights and their rates
    probe = {c: np.zeros(1) for c in list(model.channels) + list(model.ride_height_channels)}
    names = body_equations(model, probe, values).names
    warns: list[str] = []
    outside = [k for k in out.free if k not in names]
    for k in outside:
        out[k].vary = False
    if outside:
        held = ", ".join(f"{k}={values[k]:g} {model.spec(k).unit}" for k in outside)
        warns.append(f"road unknown: {', '.join(outside)} act only through the wheels' "
                     f"equations, which hold the unmeasured road: not monitored, held at {held}")
    inside = [k for k in names if k in out.free]
    if inside and len(inside) == len(names):
        m0 = next((k for k in inside if model.spec(k).kind in ("mass", "inertia")), inside[0])
        out[m0].vary = False
        warns.append(f"road unknown: the body equations are homogeneous in "
                     f"{', '.join(names)} (only their ratios are determined); holding {m0} at "
                     f"{values[m0]:g} {model.spec(m0).unit} (give --fix {m0}=VALUE)")
    return out, warns


class RoadFreeWindowEstimator:
    """Each window's body equations fitted with the road unknown (module docstring).

    ``params``: held values and the free parameters' given values (SI), those outside the
    body equations held (:func:`road_unknown_params`); of ``config`` only the window, step,
    ``max_missing``, ``min_deflection`` and ``sigma_floor`` apply. Raises
    :class:`InputError` when the ``channels`` form no body equation with a free parameter.
    """

    name = "nm"
    road = "unknown"
    own_track = False

    def __init__(self, model: SuspensionModel, params: Parameters, config: WindowConfig,
                 channels: list[str], inspection: bool = True) -> None:
        self.model = model
        self.params = params.copy()
        self.config = config
        self.lag = config.window_s / 2.0
        self.lags: dict[str, float] = {}
        self.overlap = max(1.0, config.window_s / config.step_s)
        self.inspection = inspection and quarter_car_problem(model) is None
        values = self.params.valuesdict()
        probe = {c: np.zeros(1) for c in channels}
        eqs = body_equations(model, probe, values)
        self.channels = eqs.channels
        free_in = [k for k in eqs.names if k in self.params.free]
        if not eqs.rows or not free_in:
            why = "; ".join(eqs.missing) or "no free parameter enters them"
            raise InputError(f"road unknown: the stream's channels ({', '.join(channels) or 'none'}) "
                             f"form no body equation to monitor ({why}); expected the body "
                             f"accelerations and the ride heights {', '.join(model.ride_heights)}")
        self.missing = list(eqs.missing)
        self.heights = [h for h in model.ride_heights if h in channels]
        self.n_windows = 0
        self.n_skipped = 0
        self.total_cpu = 0.0

    def _skip(self, t: FloatArray, reason: str, c0: float) -> StepResult:
        self.n_skipped += 1
        self.total_cpu += time.process_time() - c0
        return StepResult(Skip(float(t[-1]), float(t[0]), self.name, reason))

    def process(self, t: FloatArray, data: Mapping[str, FloatArray]) -> StepResult:
        """Fit one window's body equations (times ``t``, s; channels SI, NaN where missing)."""
        c0 = time.process_time()
        cfg = self.config
        for c in self.channels:
            v = data.get(c)
            frac = 1.0 if v is None else 1.0 - float(np.mean(np.isfinite(v)))
            if frac > cfg.max_missing:
                return self._skip(t, f"channel {c}: {frac:.0%} of the window's samples missing "
                                     f"(> {cfg.max_missing:.0%}); gap in the data", c0)
        rms = {h: float(np.nanstd(data[h])) for h in self.heights if h in data}
        if rms and max(rms.values()) < cfg.min_deflection:
            h, top = max(rms.items(), key=lambda kv: kv[1])
            return self._skip(t, f"too little excitation: ride height {h} RMS {top * 1e3:.3g} mm "
                                 f"< {cfg.min_deflection * 1e3:.3g} mm", c0)
        meas = Measurement(np.asarray(t, dtype=float), {},
                           {c: np.asarray(data[c], dtype=float) for c in self.channels},
                           source="window")
        res = fit_road_unknown(self.model, meas, self.params, misfit_fails=False)
        if not res.success:
            why = next((w for w in reversed(res.warnings) if w.startswith("road unknown: no ")),
                       "the body equations could not be solved on this window")
            return self._skip(t, why.removeprefix("road unknown: "), c0)
        stderr = {k: float(math.hypot(v, cfg.sigma_floor * res.params[k]))
                  for k, v in res.stderr.items()}
        info: dict[str, Any] = {
            "road": "unknown", "stderr_fit": dict(res.stderr), "identifiable": res.identifiable,
            "undetermined": list(res.undetermined or []), "cost": res.cost,
            "rms_residual": dict(res.rms_residual), "band_hz": res.band_hz,
            "excitation": {"ride_height_rms": rms}, "misfit": res.misfit,
            "warnings": [w for w in res.warnings[1:]
                         if not w.startswith("not identifiable with the road unknown")]}
        if self.inspection and res.identifiable:
            add_inspection(info, res.params, self.model)
        cpu = time.process_time() - c0
        info["cpu_ms"] = 1e3 * cpu
        self.n_windows += 1
        self.total_cpu += cpu
        ev = Estimate(float(t[-1]), float(t[0]), self.name, dict(res.params), stderr, info=info)
        return StepResult(ev, dict(res.params), stderr)

    def summary(self) -> dict[str, Any]:
        """Windows fitted and skipped, CPU time (s)."""
        return {"windows": self.n_windows, "skipped": self.n_skipped, "nfev": 2 * self.n_windows,
                "cpu_s": self.total_cpu, "road": "unknown"}


def make_roadfree_estimator(spec: Any, channels: list[str], fs: float) -> RoadFreeWindowEstimator:
    """The road-unknown sliding window of a :class:`~estimator.stream.pipeline.MonitorSpec`."""
    return RoadFreeWindowEstimator(spec.model, spec.params, spec.config, channels,
                                   inspection=spec.inspection)
