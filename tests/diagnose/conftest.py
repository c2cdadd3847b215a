"""Data with undeclared effects for the diagnose tests (short records: 1.6 s at 200 Hz)."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement
from suspid.models import get_model
from suspid.models.effects import inject

from ..conftest import TABLE1

CHANNELS = ("x1", "x2", "x1_dot", "x2_dot")


def make_measurement(effects: Sequence[str], scenario: str = "bump", *, fs: float = 200.0,
                     duration: float = 1.6, noise: float = 0.005, seed: int = 0,
                     params: dict[str, float] | None = None, model: str = "quarter2",
                     extra_force=None, **scen) -> Measurement:
    """Simulate ``model`` with ``effects`` injected and white noise (fraction of each channel's std)."""
    m = get_model(model)
    p = dict(TABLE1 if params is None and model == "quarter2" else (params or m.defaults()))
    t, road, x0 = make_scenario(m, scenario, duration=duration, fs=fs, params=p, seed=seed, **scen)
    inj = inject(m, effects)
    if extra_force is not None:
        inj.model.extra_force.append(extra_force)
        from suspid.simulate import simulate_ode
        out = inj.measure(t, simulate_ode(inj.model, p, t, road, x0))
    else:
        out = inj.simulate(p, t, road, x0)
    rng = np.random.default_rng(seed + 101)
    chans = [c for c in m.channels if not c.endswith("_ddot")]
    meas = {c: out[c] + noise * np.std(out[c]) * rng.standard_normal(t.size) for c in chans}
    rd = {k: v for k, v in road.items()}
    return Measurement(t, rd, meas, [], f"{model}:{scenario}:{','.join(effects) or 'none'}")
