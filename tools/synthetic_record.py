"""Synthetic records with undeclared effects (the diagnose tests, ``tools/diagnose_matrix.py``,
``tools/noise_sweep.py``)."""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement
from suspid.models import get_model
from suspid.models.base import ForceFn
from suspid.effects import Effect, inject
from suspid.simulate import simulate_ode


def synthetic_record(model: str, effects: Sequence["str | Effect"], scenario: str = "bump", *,
                     params: Mapping[str, float] | None = None, fs: float = 200.0,
                     duration: float = 1.6, noise: float = 0.005, seed: int = 0,
                     extra_force: ForceFn | None = None, noise_seed: int | None = None,
                     **scen: Any) -> Measurement:
    """Simulate ``model`` with ``effects`` nobody declared and return the noisy record.

    ``effects`` are spec strings (``"coulomb_friction:F=120"``) or effect objects; ``scenario`` a
    scenario name with options ``**scen``; ``params`` the truth (SI, default the model's); ``fs``
    (Hz), ``duration`` (s); ``noise`` the white noise per channel as a fraction of its std, seeded
    by ``noise_seed`` (default ``seed + 101``; ``suspid simulate --seed S`` draws ``noise_seed=S``);
    ``extra_force(t, x, u, params)`` a further generalised force (N, N m), integrated by
    ``solve_ivp``. Returns positions and velocities with noise, the road without.
    """
    m = get_model(model)
    p = dict(m.defaults(), **(params or {}))
    t, road, x0 = make_scenario(m, scenario, duration=duration, fs=fs, params=p, seed=seed, **scen)
    inj = inject(m, effects)
    if extra_force is not None:
        inj.model.extra_force.append(extra_force)
        out = inj.measure(t, simulate_ode(inj.model, p, t, road, x0))
    else:
        out = inj.simulate(p, t, road, x0)
    rng = np.random.default_rng(seed + 101 if noise_seed is None else noise_seed)
    chans = [c for c in m.channels if not c.endswith("_ddot")]
    meas = {c: out[c] + noise * np.std(out[c]) * rng.standard_normal(t.size) for c in chans}
    names = ",".join(str(e) for e in effects) or "none"
    return Measurement(t, dict(road), meas, [], f"{model}:{scenario}:{names}")


__all__ = ["synthetic_record"]
