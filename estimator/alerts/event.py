"""What every parameter event (alert, clear, forecast, withdrawal) shares: identity and units.

:class:`estimator.alerts.AlertEvent` and :class:`estimator.alerts.ForecastEvent` derive from
:class:`ParameterEvent`, so the deduplicating identity of the alert store and the pieces of
their messages are built in one place.
"""
from __future__ import annotations


class ParameterEvent:
    """Mixin of the parameter events (dataclasses declaring these attributes).

    Attributes
    ----------
    kind : str
        ``"alert"``, ``"clear"``, ``"forecast"`` or ``"forecast_withdrawn"``.
    t : float
        Data time of the event (s).
    parameter, model, unit : str
    limit, nominal : float
        The alert limit ``(1 - drop) x nominal`` and the nominal value (SI).
    """

    kind: str
    t: float
    parameter: str
    model: str
    unit: str
    limit: float
    nominal: float

    @property
    def id(self) -> str:
        """Deterministic identity of the event (deduplication across restarts)."""
        return f"{self.model}:{self.parameter}:{self.kind}@{self.t:.6f}"

    @property
    def unit_suffix(self) -> str:
        """``" <unit>"`` for the messages, or ``""``."""
        return f" {self.unit}" if self.unit else ""

    @property
    def limit_pct(self) -> float:
        """The limit as a percentage of nominal (NaN without a nominal)."""
        return 100.0 * self.limit / self.nominal if self.nominal else float("nan")
