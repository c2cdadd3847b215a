"""When is a parameter *confidently* below its limit? Confidence bound, persistence, hysteresis.

An alert is raised when the *upper* bound ``v + z s`` stays below ``(1 - drop) N`` for
``persistence_s`` and ``min_count`` estimates, cleared when the *lower* bound stays above
``(1 - drop + hysteresis) N`` likewise; skipped windows neither confirm nor reset. One event
per episode: ``t`` the window that confirmed it, ``onset`` the first.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Protocol

from estimator.alerts.event import ParameterEvent
from suspid.errors import UsageError
from suspid.models import get_model


@dataclass
class AlertConfig:
    """Alert settings (``nominal`` SI of every watched parameter)."""

    nominal: dict[str, float] = field(default_factory=dict)
    drop: float = 0.3  # alert when confidently below (1 - drop) x nominal
    z: float = 2.326  # one-sided normal quantile of the bound (99 %)
    persistence_s: float = 1.5  # data time (s) the condition must hold ...
    min_count: int = 2  # ... and consecutive estimates
    hysteresis: float = 0.05  # clear only above (1 - drop + hysteresis) x nominal
    level: float = 0.90  # two-sided level of a fleet forecast interval
    horizon_days: float = 365.0  # the fleet forecasts no further ahead of the latest drive

    @classmethod
    def per_drive(cls, **settings: Any) -> "AlertConfig":
        """The fleet's settings: one drive confidently below is enough."""
        return cls(**{"persistence_s": 0.0, "min_count": 1, **settings})

    def nominal_of(self, model: str, name: str) -> float:
        """``name``'s nominal value (SI): the configured one, else the model's default."""
        if name in self.nominal:
            return float(self.nominal[name])
        return float(get_model(model).spec(name).default)

    def to_json(self) -> dict[str, Any]:
        """The settings as a JSON object (stored with each fleet run in its history)."""
        return {"nominal": dict(self.nominal), "drop": self.drop, "z": self.z,
                "persistence_s": self.persistence_s, "min_count": self.min_count,
                "hysteresis": self.hysteresis, "level": self.level,
                "horizon_days": self.horizon_days}

    def validate(self) -> None:
        """Raise :class:`UsageError` for settings that cannot work."""
        if not 0 < self.drop < 1:
            raise UsageError(f"--alert-drop: expected a fraction in (0, 1), got {self.drop}")
        if self.persistence_s < 0 or self.min_count < 1:
            raise UsageError(f"alert persistence must be >= 0 s and >= 1 estimate, got "
                             f"{self.persistence_s} s, {self.min_count}")
        if not 0 <= self.hysteresis < self.drop:
            raise UsageError(f"alert hysteresis must be in [0, drop), got {self.hysteresis}")
        for k, v in self.nominal.items():
            if not (v > 0 and math.isfinite(v)):
                raise UsageError(f"--nominal {k}: expected a finite value > 0, got {v}")

    def limit(self, name: str) -> float:
        return (1.0 - self.drop) * self.nominal[name]

    def clear_level(self, name: str) -> float:
        return (1.0 - self.drop + self.hysteresis) * self.nominal[name]


@dataclass
class AlertEvent(ParameterEvent):
    """An alert (``kind`` ``"alert"``) or its clear (``"clear"``).

    ``t`` is the data time (s) that confirmed it, ``onset`` the episode's first estimate;
    ``value``, ``stderr``, ``nominal`` (SI); ``bound`` the confidence bound that decided;
    ``severity`` ``"warning"``, ``"critical"`` below ``(1 - 2 drop) N``, ``"info"`` for a clear.
    """

    kind: str
    t: float
    onset: float
    parameter: str
    value: float
    stderr: float
    nominal: float
    bound: float
    limit: float
    severity: str
    model: str
    unit: str = ""

    @property
    def message(self) -> str:
        u, pct = self.unit_suffix, self.limit_pct
        if self.kind == "alert":
            return (f"{self.parameter} = {self.value:.6g}{u} is confidently below {pct:.0f} % of "
                    f"nominal {self.nominal:.6g}{u} (99 % upper bound {self.bound:.6g}{u} < "
                    f"{self.limit:.6g}{u} since t={self.onset:.2f} s); {self.severity}: "
                    f"inspect the {'damper' if self.parameter.startswith('c') else 'part'}")
        return (f"{self.parameter} = {self.value:.6g}{u} is back above the clear level "
                f"(99 % lower bound {self.bound:.6g}{u}); alert cleared")

    def to_json(self) -> dict[str, Any]:
        """The monitor's JSON line (contract fields first)."""
        return {"type": self.kind, "t": self.t, "parameter": self.parameter, "value": self.value,
                "nominal": self.nominal, "message": self.message, "stderr": self.stderr,
                "bound": self.bound, "limit": self.limit, "onset": self.onset,
                "severity": self.severity, "model": self.model, "id": self.id}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> "AlertEvent":
        return cls(kind=str(d["type"]), t=float(d["t"]), onset=float(d.get("onset", d["t"])),
                   parameter=str(d["parameter"]), value=float(d["value"]),
                   stderr=float(d.get("stderr") or 0.0), nominal=float(d["nominal"]),
                   bound=float(d.get("bound") or d["value"]), limit=float(d.get("limit") or 0.0),
                   severity=str(d.get("severity", "warning")), model=str(d.get("model", "")))


class AlertSink(Protocol):
    """Anything that delivers an event: a callback (stdout, a file), the DBC alert frame on a bus."""

    def emit(self, event: ParameterEvent) -> None: ...


@dataclass
class _State:
    active: bool = False
    since: float | None = None
    count: int = 0


@dataclass
class AlertEngine:
    """Per-parameter alert state machines feeding ``sinks`` through a durable ``store``.

    The store (an :class:`~estimator.alerts.store.AlertStore`) is written before any sink
    sees an event, and events already in it are suppressed: a restarted monitor neither
    loses nor repeats alerts. ``model`` and ``units`` go into the frames and messages.
    """

    config: AlertConfig
    model: str
    units: dict[str, str] = field(default_factory=dict)
    store: Any = None
    sinks: list[AlertSink] = field(default_factory=list)
    states: dict[str, _State] = field(default_factory=dict)
    emitted: list[Any] = field(default_factory=list)
    suppressed: int = 0

    def __post_init__(self) -> None:
        self.config.validate()
        for k in self.config.nominal:
            self.states[k] = _State()
        if self.store is not None:
            for k, ev in self.store.last_event.items():
                if k in self.states and ev.kind == "alert":
                    self.states[k].active = True

    def update(self, t: float, values: Mapping[str, float], stderr: Mapping[str, float]
               ) -> list[AlertEvent]:
        """Fold in one estimate (data time ``t``); returns the events emitted now."""
        cfg = self.config
        out: list[AlertEvent] = []
        for k, st in self.states.items():
            if k not in values or k not in stderr:
                continue
            v, s = float(values[k]), float(stderr[k])
            if not (math.isfinite(v) and math.isfinite(s)):
                # an unidentifiable window says nothing: neither confirms nor resets
                continue
            nom = cfg.nominal[k]
            if not st.active:
                bound = v + cfg.z * s
                cond = bound < cfg.limit(k)
            else:
                bound = v - cfg.z * s
                cond = bound > cfg.clear_level(k)
            if not cond:
                st.since, st.count = None, 0
                continue
            if st.since is None:
                st.since = t
            st.count += 1
            if t - st.since + 1e-9 < cfg.persistence_s or st.count < cfg.min_count:
                continue
            kind = "clear" if st.active else "alert"
            severity = "critical" if (kind == "alert" and bound < (1 - 2 * cfg.drop) * nom) else \
                ("info" if kind == "clear" else "warning")
            ev = AlertEvent(kind, float(t), float(st.since), k, v, s, nom, bound, cfg.limit(k),
                            severity, self.model, self.units.get(k, ""))
            st.active = not st.active
            st.since, st.count = None, 0
            if self.publish(ev):
                out.append(ev)
        return out

    def publish(self, ev: Any) -> bool:
        """Write ``ev`` to the store, then to the sinks; ``False`` when the store has it already."""
        if self.store is not None:
            if not self.store.is_new(ev):
                self.suppressed += 1
                return False
            self.store.append(ev)
        for s in self.sinks:
            s.emit(ev)
        self.emitted.append(ev)
        return True
