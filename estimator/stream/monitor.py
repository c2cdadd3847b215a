"""The monitor: windows of a stream -> estimates (NM or EKF) -> tracking, inspection, alerts.

:class:`NMWindowEstimator` fits every window (:class:`~estimator.stream.window.SlidingWindowIdentifier`)
and runs the virtual damper test on quarter-car estimates; the EKF baseline has the same
``process(t, data)`` interface. :class:`StreamMonitor` turns results into typed events,
tracks them (:class:`~estimator.stream.tracker.TrendTracker`) and feeds alerts and forecasts.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

from estimator.alerts import AlertEngine, ForecastEngine
from estimator.identify import Parameters
from estimator.inspection import inspect, quarter_car_problem
from estimator.stream.config import WindowConfig
from estimator.stream.events import Estimate, Notice, Skip, Summary
from estimator.stream.misfit import MisfitWatch, misfit_shares
from estimator.stream.offsets import OffsetStage
from estimator.stream.tracker import TrendTracker
from estimator.stream.window import SlidingWindowIdentifier
from suspid.models.base import FloatArray, SuspensionModel


@dataclass
class StepResult:
    """What one window produced: its event, the values and stderr for the tracker (``None``
    when skipped) and notices about the run decided on it."""

    event: Estimate | Skip
    values: dict[str, float] | None = None
    stderr: dict[str, float] | None = None
    notices: list[Notice] = field(default_factory=list)

    @property
    def line(self) -> dict[str, Any]:
        """The event's JSON line."""
        return self.event.to_json()


def fill_road_gaps(model: SuspensionModel, data: Mapping[str, FloatArray], t: FloatArray,
                   max_missing: float) -> tuple[dict[str, FloatArray], list[str], str]:
    """Bridge short gaps in road channels by linear interpolation (reported, never silent).
    Returns the data, warnings, and a skip reason when a road misses over ``max_missing``."""
    out = dict(data)
    warns: list[str] = []
    for r in list(model.roads) + [f"{r}_dot" for r in model.roads]:
        v = data.get(r)
        if v is None:
            continue
        ok = np.isfinite(v)
        if ok.all():
            continue
        frac = 1.0 - float(ok.mean())
        if r.endswith("_dot"):
            out.pop(r)  # differentiate the displacement instead
            warns.append(f"road velocity {r}: {frac:.0%} missing; differentiated from "
                         f"{r[:-4]} instead")
            continue
        if frac > max_missing or ok.sum() < 2:
            return out, warns, (f"road channel {r}: {frac:.0%} of the window's samples missing "
                                f"(> {max_missing:.0%}); gap in the data")
        out[r] = np.interp(t, t[ok], v[ok])
        warns.append(f"road channel {r}: {int((~ok).sum())} missing samples bridged by linear "
                     "interpolation")
    return out, warns, ""


def add_inspection(info: dict[str, Any], params: Mapping[str, float], model: SuspensionModel) -> None:
    """Add the virtual damper test of ``params`` (SI) to an estimate's ``info``."""
    try:
        info["inspection"] = inspect(params, model).to_json()
    except (np.linalg.LinAlgError, ValueError) as exc:
        info["inspection"] = None
        info["warnings"].append(f"virtual damper test failed: {exc}")


class NMWindowEstimator:
    """Sliding-window Nelder-Mead estimates with the virtual damper test (``inspection``).

    ``lag`` (``window_s / 2``: an estimate describes the window's middle) and ``overlap``
    (``window_s / step_s``) tell the tracker how to fold the estimates in.
    """

    name = "nm"
    own_track = False

    def __init__(self, model: SuspensionModel, params: Parameters, config: WindowConfig,
                 channels: list[str], inspection: bool = True) -> None:
        self.model = model
        self.ident = SlidingWindowIdentifier(model, params, config, channels)
        self.config = config
        self.lag = config.window_s / 2.0
        self.lags = {k: 0.0 for k in config.drift}
        self.overlap = max(1.0, config.window_s / config.step_s)
        self.inspection = inspection and quarter_car_problem(model) is None
        #: misfit windows (their fit far above the noise floor) and the one warning
        self.misfit = MisfitWatch({k: float(params[k].value) for k in params
                                   if k not in params.free})

    def process(self, t: FloatArray, data: Mapping[str, FloatArray]) -> StepResult:
        data, warns, reason = fill_road_gaps(self.model, data, t, self.config.max_missing)
        if reason:
            self.ident.n_skipped += 1
            return StepResult(Skip(float(t[-1]), float(t[0]), self.name, reason))
        res = self.ident.process(t, data)
        line = res.to_json()
        if res.skipped:
            return StepResult(Skip(res.t, res.t_start, self.name, res.reason,
                                   {"excitation": res.excitation}))
        info = {k: v for k, v in line.items()
                if k not in ("type", "t", "t_start", "params", "stderr")}
        info["warnings"] = warns + list(info.get("warnings", []))
        if self.inspection:
            add_inspection(info, res.params, self.model)
        is_misfit, notice = self.misfit.update(
            res.t, res.noise_floor_ratio,
            misfit_shares(res.noise_floor_ratio, res.rms_residual, data))
        info["misfit"] = is_misfit
        finite = {k: v for k, v in res.stderr.items() if math.isfinite(v)}
        return StepResult(Estimate(res.t, res.t_start, self.name, dict(res.params),
                                   dict(res.stderr), info=info),
                          dict(res.params), finite if res.identifiable else {},
                          [notice] if notice is not None else [])

    def summary(self) -> dict[str, Any]:
        i = self.ident
        return {"windows": i.n_windows, "skipped": i.n_skipped, "nfev": i.total_nfev,
                "cpu_s": i.total_cpu, "misfit_windows": self.misfit.count}


@dataclass
class StreamMonitor:
    """Drive an estimator window by window: track, alert, forecast, hand events to ``emit``.

    Alerts are decided on the tracked value at the window's end, forecasts on the tracked
    trend; an estimator that is itself a tracker (``own_track``: the EKF) feeds the alerts
    its own estimate. ``offsets`` removes a sensor offset found on the first excited window
    (:mod:`estimator.stream.offsets`); the tracker is built from the estimator's ``lag`` and
    ``overlap`` when not given.
    """

    estimator: Any
    emit: Callable[[Any], None]
    alerts: AlertEngine | None = None
    tracker: TrendTracker | None = None
    forecasts: ForecastEngine | None = None
    offsets: OffsetStage | None = None
    lines: int = 0
    started: float = field(default_factory=time.perf_counter)
    cpu_started: float = field(default_factory=time.process_time)
    t_first: float = math.nan
    t_last: float = math.nan

    def _tracker(self) -> TrendTracker:
        if self.tracker is None:
            nominal = dict(self.alerts.config.nominal) if self.alerts is not None else {}
            # a filter's own outputs are serially correlated: their scatter says nothing
            # about their error, so only window estimates are calibrated
            self.tracker = TrendTracker(lag=float(getattr(self.estimator, "lag", 0.0)),
                                        lags=dict(getattr(self.estimator, "lags", {})),
                                        overlap=float(getattr(self.estimator, "overlap", 1.0)),
                                        nominal=nominal,
                                        calibrate=not getattr(self.estimator, "own_track", False))
        return self.tracker

    def window(self, t: FloatArray, data: Mapping[str, FloatArray]) -> StepResult:
        """Process one window (times ``t``, channels ``data``)."""
        if not math.isfinite(self.t_first):
            self.t_first = float(t[0])
        self.t_last = float(t[-1])
        told = None
        if self.offsets is not None:
            data, told = self.offsets.process(t, data)
        res = self.estimator.process(t, data)
        if told is not None:
            res.notices.insert(0, told)
        ev = res.event
        tracked: dict[str, dict[str, float]] = {}
        if isinstance(ev, Estimate) and res.values is not None and res.stderr:
            tracked = self._tracker().update(ev.t, res.values, res.stderr)
            if ev.track is None:
                ev.track = tracked
        self.emit(ev)
        self.lines += 1
        stage = self.offsets
        kept = stage.offset if stage is not None and not stage.remove else None
        for n in res.notices:
            if n.kind == "misfit" and stage is not None and kept is not None:
                # the likeliest cause is the one already found
                n.message += (f". A sensor offset was found and kept: "
                              f"{kept.describe(stage.model)} (window.offset = \"keep\"); \"remove\" "
                              "subtracts it")
                n.fields["offset_kept"] = dict(kept.values)
            self.emit(n)
            self.lines += 1
        if isinstance(ev, Estimate) and res.values is not None and res.stderr:
            if self.alerts is not None:
                if getattr(self.estimator, "own_track", False):
                    self.alerts.update(ev.t, res.values, res.stderr)
                else:
                    self.alerts.update(ev.t, {k: v["value"] for k, v in tracked.items()},
                                       {k: v["stderr"] for k, v in tracked.items()})
            if self.forecasts is not None:
                self.forecasts.update(self._tracker().trends(ev.t))
        return res

    def summary(self, extra: Mapping[str, Any] | None = None) -> Summary:
        """The closing ``summary`` event: counts, budget, speed."""
        wall = time.perf_counter() - self.started
        cpu = time.process_time() - self.cpu_started
        span = self.t_last - self.t_first if math.isfinite(self.t_first) else 0.0
        out: dict[str, Any] = {"baseline": self.estimator.name,
                               "data_s": span, "wall_s": wall, "cpu_s": cpu,
                               "realtime_factor": span / wall if wall > 0 else None}
        out.update(self.estimator.summary())
        if self.offsets is not None:
            out["offset"] = self.offsets.summary()
        if self.alerts is not None:
            out["alerts"] = sum(1 for e in self.alerts.emitted if e.kind == "alert")
            out["forecasts"] = sum(1 for e in self.alerts.emitted if e.kind == "forecast")
            out["alerts_suppressed_as_logged"] = self.alerts.suppressed
        out.update(extra or {})
        return Summary(out)


def make_nm_estimator(spec: Any, channels: list[str], fs: float) -> NMWindowEstimator:
    """The sliding-window estimator of a :class:`~estimator.stream.pipeline.MonitorSpec`."""
    meas = [c for c in channels if c in spec.model.channels]
    return NMWindowEstimator(spec.model, spec.params, spec.config, meas,
                             inspection=spec.inspection)
