"""Typed events of the monitor: what a window, the tracker and the alerting produce.

The monitor (:mod:`estimator.stream.pipeline`) passes these objects to its sinks; only the
sinks turn them into JSON lines (:meth:`to_json`) or text. Alerts and clears are
:class:`estimator.alerts.AlertEvent`, forecasts :class:`estimator.alerts.ForecastEvent`; both
share their identity (``model:parameter:kind@t``, the alert store's deduplication key) and
message pieces through :class:`estimator.alerts.event.ParameterEvent`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Union

from estimator.alerts.engine import AlertEvent
from estimator.alerts.forecast import ForecastEvent


@dataclass
class Estimate:
    """One window's parameter estimate.

    Attributes
    ----------
    t, t_start : float
        Data time (s) at the window's end and start.
    baseline : str
        The estimator (``"nm"``, ``"ekf"``, ``"output_only"``).
    params : dict
        Every parameter value (SI), fixed ones included.
    stderr : dict
        Standard error of each estimated parameter (SI).
    track : dict or None
        The tracker's state at ``t``: ``parameter -> {"value", "stderr", "rate", "rate_stderr"}``
        (SI, SI/s); the alerts and forecasts are decided on it.
    info : dict
        Everything else the estimator reports (evaluations, CPU, excitation, warnings, ...),
        as JSON-ready values.
    """

    t: float
    t_start: float
    baseline: str
    params: dict[str, float]
    stderr: dict[str, float]
    track: dict[str, dict[str, float]] | None = None
    info: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """The ``estimate`` JSON line."""
        out: dict[str, Any] = {"type": "estimate", "t": self.t, "t_start": self.t_start,
                               "params": self.params, "stderr": self.stderr}
        out.update(self.info)
        out["baseline"] = self.baseline
        if self.track is not None:
            out["track"] = self.track
        return out


@dataclass
class Skip:
    """A window that was not fitted, with the reason (too little excitation, a gap, ...)."""

    t: float
    t_start: float
    baseline: str
    reason: str
    info: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """The ``skip`` JSON line."""
        out: dict[str, Any] = {"type": "skip", "t": self.t, "t_start": self.t_start,
                               "reason": self.reason}
        out.update(self.info)
        out["baseline"] = self.baseline
        return out


@dataclass
class Notice:
    """A warning about the run as a whole, said once (e.g. the fits persistently miss).

    Attributes
    ----------
    t : float
        Data time (s) of the window that decided it.
    kind : str
        What it is about (``"misfit"``).
    message : str
        One plain sentence or two: what was seen, the likely causes, what to do.
    fields : dict
        The numbers behind it, as JSON-ready values.
    """

    t: float
    kind: str
    message: str
    fields: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """The ``warning`` JSON line."""
        out: dict[str, Any] = {"type": "warning", "t": self.t, "kind": self.kind}
        out.update(self.fields)
        out["message"] = self.message
        return out


@dataclass
class Summary:
    """The closing line: counts, CPU and wall time, frames, alerts."""

    fields: dict[str, Any]

    def to_json(self) -> dict[str, Any]:
        """The ``summary`` JSON line."""
        return dict({"type": "summary"}, **self.fields)


Event = Union[Estimate, Skip, Notice, AlertEvent, ForecastEvent, Summary]
