"""Synthetic records with undeclared effects (the diagnose tests and ``tools/diagnose_matrix.py``)."""
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

    Parameters
    ----------
    model : str
        A registered model name.
    effects : sequence
        Effect spec strings (``"coulomb_friction:F=120"``) or effect objects.
    scenario : str
        Scenario name (``bump``, ``curb``, ``iso8608``, ``initial``); ``**scen`` its options.
    params : mapping, optional
        True parameters (SI; default the model's defaults).
    fs, duration : float
        Sample rate (Hz) and record length (s).
    noise : float
        White noise on every channel, as a fraction of the channel's standard deviation.
    seed, noise_seed : int
        Seed of the scenario; of the noise (default ``seed + 101``; ``suspid simulate --seed S``
        draws the same noise as ``noise_seed=S``).
    extra_force : callable, optional
        A further generalised force ``f(t, x, u, params)`` (N, N m), integrated by ``solve_ivp``.

    Returns
    -------
    Measurement
        Positions and velocities (no accelerations) with noise, the road without.
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
