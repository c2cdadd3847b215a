"""What every parameter event (alert, clear, forecast, withdrawal) shares: identity and units."""
from __future__ import annotations


class ParameterEvent:
    """Mixin of the parameter events (dataclasses declaring these attributes): ``kind``, data
    time ``t`` (s), ``limit`` and ``nominal`` (SI)."""

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
