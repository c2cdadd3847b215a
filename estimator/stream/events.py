"""Typed events of the monitor; only the sinks turn them into JSON lines (``to_json``) or text.

Alerts and forecasts are :class:`estimator.alerts.engine.AlertEvent` and
:class:`estimator.alerts.ForecastEvent`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass
class Estimate:
    """One window's estimate: data times (s) of the window's end and start, the estimator
    (``baseline``), every parameter and the free ones' stderr (SI), the tracker's state at
    ``t`` (``track``: ``{"value", "stderr", "rate", "rate_stderr"}`` per parameter, what the
    alerts and forecasts are decided on) and everything else JSON-ready in ``info``."""

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
                               "params": self.params, "stderr": self.stderr, **self.info,
                               "baseline": self.baseline}
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
        return {"type": "skip", "t": self.t, "t_start": self.t_start, "reason": self.reason,
                **self.info, "baseline": self.baseline}


@dataclass
class Notice:
    """A warning about the run as a whole, said once: data time (s) of the window that decided
    it, ``kind`` (``"misfit"``, ``"offset"``), a plain ``message`` and the numbers behind it."""

    t: float
    kind: str
    message: str
    fields: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """The ``warning`` JSON line."""
        return {"type": "warning", "t": self.t, "kind": self.kind, **self.fields,
                "message": self.message}


@dataclass
class Summary:
    """The closing line: counts, CPU and wall time, frames, alerts."""

    fields: dict[str, Any]

    def to_json(self) -> dict[str, Any]:
        """The ``summary`` JSON line."""
        return dict({"type": "summary"}, **self.fields)

