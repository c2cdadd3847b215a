"""The monitor: windows of a stream -> estimates (NM or EKF) -> tracking, inspection, alerts.

:class:`NMWindowEstimator` (the default) fits every window with
:class:`~estimator.stream.window.SlidingWindowIdentifier`, tracks the parameters
(:class:`~estimator.stream.tracker.ParameterTracker`) and runs the virtual damper test
(:mod:`estimator.inspection`) on each estimate of a quarter car. The EKF baseline
(:class:`estimator.ekf.EKFWindowEstimator`) has the same ``process(t, data)`` interface and
consumes only the samples it has not seen. :class:`StreamMonitor` turns their results into
JSON lines and feeds the alert engine.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Protocol

import numpy as np

from estimator.alerts import AlertEngine
from estimator.identify import Parameters
from estimator.stream.config import WindowConfig
from estimator.stream.tracker import ParameterTracker
from estimator.stream.window import SlidingWindowIdentifier
from suspid.models.base import FloatArray, SuspensionModel


@dataclass
class StepResult:
    """What one window produced.

    Attributes
    ----------
    line : dict
        The JSON line (``estimate`` or ``skip``).
    values, stderr : dict or None
        Parameter values and standard errors for the alert engine (``None`` when skipped).
    """

    line: dict[str, Any]
    values: dict[str, float] | None = None
    stderr: dict[str, float] | None = None


class WindowEstimator(Protocol):
    """Anything that turns a window of samples into a :class:`StepResult`."""

    name: str

    def process(self, t: FloatArray, data: Mapping[str, FloatArray]) -> StepResult: ...

    def summary(self) -> dict[str, Any]: ...


def fill_road_gaps(model: SuspensionModel, data: Mapping[str, FloatArray], t: FloatArray,
                   max_missing: float) -> tuple[dict[str, FloatArray], list[str], str]:
    """Bridge short gaps in road channels by linear interpolation (reported, never silent).

    Returns the new data dict, warnings, and a skip reason when a road channel misses more
    than ``max_missing`` of the window (or everything).
    """
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


class NMWindowEstimator:
    """Sliding-window Nelder-Mead estimates with tracking and the virtual damper test.

    Parameters
    ----------
    model : SuspensionModel
    params : Parameters
        Nominal starting values and fixed parameters.
    config : WindowConfig
    channels : list of str
        Measured channels in the stream.
    inspection : bool
        Add EUSAMA / EGEA results to every quarter-car estimate.
    track_q : float
        Random-walk intensity of the tracker (1/sqrt(s)).
    """

    name = "nm"

    def __init__(self, model: SuspensionModel, params: Parameters, config: WindowConfig,
                 channels: list[str], inspection: bool = True, track_q: float = 0.01) -> None:
        self.model = model
        self.ident = SlidingWindowIdentifier(model, params, config, channels)
        self.config = config
        self.tracker = ParameterTracker(q=track_q, overlap=max(1.0, config.window_s / config.step_s))
        self.inspection = inspection and model.name == "quarter2"

    def process(self, t: FloatArray, data: Mapping[str, FloatArray]) -> StepResult:
        data, warns, reason = fill_road_gaps(self.model, data, t, self.config.max_missing)
        if reason:
            self.ident.n_skipped += 1
            return StepResult({"type": "skip", "t": float(t[-1]), "t_start": float(t[0]),
                               "reason": reason, "baseline": self.name})
        res = self.ident.process(t, data)
        line = res.to_json()
        line["baseline"] = self.name
        if res.skipped:
            return StepResult(line)
        line["warnings"] = warns + line.get("warnings", [])
        line["track"] = self.tracker.update(res.t, res.params, res.stderr)
        if self.inspection:
            from estimator.inspection import inspect

            try:
                line["inspection"] = inspect(res.params, self.model).to_json()
            except (np.linalg.LinAlgError, ValueError) as exc:
                line["inspection"] = None
                line["warnings"].append(f"virtual damper test failed: {exc}")
        finite = {k: v for k, v in res.stderr.items() if math.isfinite(v)}
        return StepResult(line, dict(res.params), finite if res.identifiable else {})

    def summary(self) -> dict[str, Any]:
        i = self.ident
        return {"windows": i.n_windows, "skipped": i.n_skipped, "nfev": i.total_nfev,
                "cpu_s": i.total_cpu}


@dataclass
class StreamMonitor:
    """Drive an estimator window by window; print JSON lines; raise alerts.

    Parameters
    ----------
    estimator : WindowEstimator
    emit : callable
        Receives every JSON line (dict).
    alerts : AlertEngine, optional
    """

    estimator: Any
    emit: Callable[[dict[str, Any]], None]
    alerts: AlertEngine | None = None
    lines: int = 0
    started: float = field(default_factory=time.perf_counter)
    cpu_started: float = field(default_factory=time.process_time)
    t_first: float = math.nan
    t_last: float = math.nan

    def window(self, t: FloatArray, data: Mapping[str, FloatArray]) -> StepResult:
        """Process one window (times ``t``, channels ``data``)."""
        if not math.isfinite(self.t_first):
            self.t_first = float(t[0])
        self.t_last = float(t[-1])
        res = self.estimator.process(t, data)
        self.emit(res.line)
        self.lines += 1
        if self.alerts is not None and res.values is not None and res.stderr:
            self.alerts.update(float(res.line["t"]), res.values, res.stderr)
        return res

    def summary(self, extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """The closing ``summary`` line: counts, budget, speed."""
        wall = time.perf_counter() - self.started
        cpu = time.process_time() - self.cpu_started
        span = self.t_last - self.t_first if math.isfinite(self.t_first) else 0.0
        out: dict[str, Any] = {"type": "summary", "baseline": self.estimator.name,
                               "data_s": span, "wall_s": wall, "cpu_s": cpu,
                               "realtime_factor": span / wall if wall > 0 else None}
        out.update(self.estimator.summary())
        if self.alerts is not None:
            out["alerts"] = sum(1 for e in self.alerts.emitted if e.kind == "alert")
            out["alerts_suppressed_as_logged"] = self.alerts.suppressed
        out.update(extra or {})
        return out
