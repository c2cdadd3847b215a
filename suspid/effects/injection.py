"""Building effects from names and specs, and injecting undeclared effects into a
simulation (tests, demos, the sensor node).
"""

import copy
import math
from dataclasses import dataclass
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from suspid.effects.base import Effect, PhysicalEffect, SensorEffect, effect_classes
from suspid.errors import UsageError
from suspid.models.base import FloatArray, SuspensionModel
from suspid.nlsim import simulate_effects
from suspid.simulate import simulate

#: longest internal step (s) of an injected simulation
MAX_STEP = 2.5e-4


def make_effect(name: str, **values: Any) -> Effect:
    """Build the effect called ``name`` with parameters ``values`` (UsageError: unknown, bad)."""
    reg = effect_classes()
    try:
        cls = reg[name]
    except KeyError:
        raise UsageError(f"unknown effect {name!r}; expected one of {', '.join(reg)}") from None
    return cls(**values)


def parse_effect(spec: str) -> Effect:
    """Parse ``"NAME"`` or ``"NAME:key=value,key=value"`` into an effect (list items joined by
    ``+``: ``sensor_delay:channels=x1+x1_dot,delay_s=0.01``)."""
    name, _, rest = spec.strip().partition(":")
    values: dict[str, Any] = {}
    for item in (s for s in rest.split(",") if s.strip()):
        k, sep, v = item.partition("=")
        if not sep or not k.strip():
            raise UsageError(f"effect {spec!r}: expected NAME:key=value,..., got item {item!r}")
        values[k.strip()] = v.strip()
    return make_effect(name.strip(), **values)


def as_effect(e: "Effect | str | Mapping[str, Any]") -> Effect:
    """Accept an :class:`Effect`, a spec string or ``{"name": ..., "params": {...}}``."""
    if isinstance(e, Effect):
        return e
    if isinstance(e, str):
        return parse_effect(e)
    if isinstance(e, Mapping) and "name" in e:
        return make_effect(str(e["name"]), **dict(e.get("params", {})))
    raise UsageError(f"expected an effect, a 'NAME:key=value' string or a {{'name', 'params'}} "
                     f"mapping, got {e!r}")


@dataclass
class Injection:
    """A model with effects nobody declared to the estimator: ``model`` is a copy of ``base``
    whose ``extra_force`` carries the physical ones; ``effects`` holds them all."""

    model: SuspensionModel
    base: SuspensionModel
    effects: tuple[Effect, ...]

    @property
    def physical(self) -> list[PhysicalEffect]:
        """The physical effects (right-hand side)."""
        return [e for e in self.effects if isinstance(e, PhysicalEffect)]

    @property
    def sensor(self) -> list[SensorEffect]:
        """The sensor effects (measurement model), in the order they are applied."""
        return [e for e in self.effects if isinstance(e, SensorEffect)]

    def measure(self, t: FloatArray, channels: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
        """Apply the sensor effects to true channels (dict channel -> array, SI) at times ``t`` (s)."""
        out = dict(channels)
        for e in self.sensor:
            out = e.apply(t, out)
        return out

    def simulate(self, params: Mapping[str, float], t: FloatArray,
                 road: Mapping[str, FloatArray] | None = None,
                 x0: FloatArray | None = None) -> dict[str, FloatArray]:
        """Simulate the model with every effect (:mod:`suspid.nlsim`, steps of at most
        :data:`MAX_STEP` s) and return what the sensors report; ``params`` are the base
        model's (SI), ``t``, ``road``, ``x0`` as for :func:`suspid.simulate.simulate`."""
        t = np.asarray(t, dtype=float)
        p = dict(params)
        if not self.physical:
            out = simulate(self.base, p, t, road, x0)
        else:
            h = float(np.min(np.diff(t))) if t.size > 1 else MAX_STEP
            sub = max(1, int(math.ceil(h / MAX_STEP - 1e-9)))
            out = simulate_effects(self.base, p, self.physical, t, road, x0, substeps=sub)
        return self.measure(t, out)

    def check_record(self, t: FloatArray) -> None:
        """Raise :class:`UsageError` if an effect cannot act on a record sampled at ``t`` (s)."""
        for e in self.effects:
            why = e.record_problem(t)
            if why is not None:
                raise UsageError(f"effect {e.name}: {why}")

    def influence(self, params: Mapping[str, float], t: FloatArray,
                  road: Mapping[str, FloatArray] | None = None, x0: FloatArray | None = None,
                  combined: Mapping[str, FloatArray] | None = None) -> list[float]:
        """Per effect, the largest relative RMS change it alone makes to a channel (0: the record
        never engages it). ``params, t, road, x0`` as for :meth:`simulate`; ``combined``: its
        output with every effect, reused when there is one effect."""
        t = np.asarray(t, dtype=float)
        base = simulate(self.base, dict(params), t, road, x0)
        out: list[float] = []
        for e in self.effects:
            alone = (combined if combined is not None and len(self.effects) == 1
                     else inject(self.base, [e]).simulate(params, t, road, x0))
            worst = 0.0
            for c in self.base.channels:
                if c not in base or c not in alone:
                    continue
                ref = np.asarray(base[c], dtype=float)
                diff = np.asarray(alone[c], dtype=float) - ref
                ok = np.isfinite(diff)
                if not ok.any():
                    continue
                scale = float(np.sqrt(np.mean(ref[ok] ** 2)))
                change = float(np.sqrt(np.mean(diff[ok] ** 2)))
                if scale > 0.0:
                    worst = max(worst, change / scale)
                elif change > 0.0:
                    worst = math.inf
            out.append(worst)
        return out


def inject(model: SuspensionModel,
           effects: Iterable["Effect | str | Mapping[str, Any]"]) -> Injection:
    """Add effects to ``model`` without declaring them to the estimator.

    ``effects`` are :class:`Effect` instances, spec strings (:func:`parse_effect`) or
    ``{"name", "params"}`` mappings; ``model`` is not modified. UsageError for an unknown or
    unavailable effect, bad parameters or a channel the model does not have.
    """
    effs = tuple(as_effect(e) for e in effects)
    aug = copy.copy(model)
    aug.extra_force = list(model.extra_force)
    for e in effs:
        e.check_model(model)
        if isinstance(e, PhysicalEffect):
            aug.extra_force.append(e.force_fn(aug))
        elif isinstance(e, SensorEffect) and (bad := [c for c in e.affected() if c not in model.channels]):
            raise UsageError(f"effect {e.name}: unknown channel(s) {', '.join(bad)} for model "
                             f"{model.name}; expected any of {', '.join(model.channels)}")
    return Injection(model=aug, base=model, effects=effs)


def effects_for(model: SuspensionModel, kinds: Sequence[str] = ("physical", "sensor")) -> list[str]:
    """Names of the registered effects (plugins included) available for ``model``."""
    return [n for n, c in effect_classes().items()
            if c.kind in kinds and c.unavailable_reason(model) is None]
