"""What the simulated node's sensors see: ``initial`` (released from the seed's initial
state), ``curb`` (0.1 m at t = 0.5 s), ``bump`` (the seed's speed bump at 20 km/h),
``random`` (ISO 8608 class C at 50 km/h) and ``damper-wear`` (random road while the damper
loses damping linearly from ``wear_start`` to ``wear_to`` x nominal at the end).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

from suspid.errors import UsageError
from suspid.excitation import make_scenario
from suspid.models.base import FloatArray, SuspensionModel

SCENARIOS: tuple[str, ...] = ("initial", "curb", "bump", "random", "damper-wear")
_ALIASES = {"iso8608": "random", "random-road": "random", "damper_wear": "damper-wear",
            "wear": "damper-wear"}
#: default run length (s) per scenario
DEFAULT_DURATION = {"initial": 5.0, "curb": 5.0, "bump": 5.0, "random": 30.0, "damper-wear": 150.0}


@dataclass
class ScenarioSetup:
    """A node scenario, ready for the plant (``params(t)`` SI, ``events``: named times in s)."""

    name: str
    t: FloatArray
    road: dict[str, FloatArray]
    x0: FloatArray
    params: Callable[[float], Mapping[str, float]]
    nominal: dict[str, float]
    events: dict[str, float] = field(default_factory=dict)


def canonical_name(name: str) -> str:
    """Scenario name with aliases resolved (UsageError for unknown names)."""
    n = _ALIASES.get(name, name)
    if n not in SCENARIOS:
        raise UsageError(f"unknown scenario {name!r}; expected one of {', '.join(SCENARIOS)}")
    return n


def build_scenario(model: SuspensionModel, name: str, duration: float | None = None,
                   fs: float = 500.0, params: Mapping[str, float] | None = None,
                   seed: int = 0, wear_start: float = 20.0, wear_to: float = 0.5) -> ScenarioSetup:
    """Build the road, initial state and parameter schedule of scenario ``name`` (or an
    alias): ``duration`` (s, default :data:`DEFAULT_DURATION`), sample rate ``fs`` (Hz),
    parameter overrides (SI), road ``seed``; damper wear from ``wear_start`` (s) to
    ``wear_to`` x nominal at the end, of the first strut damper."""
    n = canonical_name(name)
    dur = DEFAULT_DURATION[n] if duration is None else float(duration)
    if not dur > 0:
        raise UsageError(f"--duration must be > 0 s, got {duration}")
    nominal = dict(model.defaults())
    if params:
        unknown = set(params) - set(nominal)
        if unknown:
            raise UsageError(f"unknown parameter(s) {', '.join(sorted(unknown))} for model "
                             f"{model.name}; expected {', '.join(nominal)}")
        nominal.update(params)
    core = {"random": "iso8608", "damper-wear": "iso8608"}.get(n, n)
    road_opts: dict[str, Any] = {"road_class": "C", "v_kmh": 50.0} if core == "iso8608" else {}
    t, road, x0 = make_scenario(model, core, duration=dur, fs=fs, params=nominal, seed=seed,
                                **road_opts)
    events: dict[str, float] = {}
    if n != "damper-wear":
        fixed = dict(nominal)
        return ScenarioSetup(n, t, road, x0, lambda _t: fixed, nominal, events)
    dname = next((s.c_name for s in model.strut_sites(nominal) if s.c_name), "c1")
    if dname not in nominal:
        raise UsageError(f"damper parameter {dname!r} not in model {model.name}")
    if not 0 < wear_to <= 1:
        raise UsageError(f"wear_to must be in (0, 1], got {wear_to}")
    c0 = nominal[dname]
    t_end = float(t[-1])
    start = min(max(0.0, wear_start), t_end)
    span = max(t_end - start, 1e-9)

    def schedule(tt: float) -> Mapping[str, float]:
        p = dict(nominal)
        frac = 0.0 if tt <= start else min(1.0, (tt - start) / span)
        p[dname] = c0 * (1.0 - (1.0 - wear_to) * frac)
        return p

    events["wear_start"] = start
    if wear_to < 0.7:
        events[f"{dname}_below_70pct"] = start + span * 0.3 / (1.0 - wear_to)
    return ScenarioSetup(n, t, road, np.asarray(x0, dtype=float), schedule, nominal, events)
