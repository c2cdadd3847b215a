"""Data with undeclared effects for the diagnose tests (short records: 1.6 s at 200 Hz)."""
from __future__ import annotations

from typing import Any, Sequence

from tools.synthetic_record import synthetic_record
from suspid.io.csvio import Measurement
from suspid.models.base import ForceFn
from suspid.effects import Effect

from ..conftest import TABLE1

CHANNELS = ("x1", "x2", "x1_dot", "x2_dot")


def make_measurement(effects: Sequence["str | Effect"], scenario: str = "bump", *, fs: float = 200.0,
                     duration: float = 1.6, noise: float = 0.005, seed: int = 0,
                     params: dict[str, float] | None = None, model: str = "quarter2",
                     extra_force: ForceFn | None = None, noise_seed: int | None = None,
                     **scen: Any) -> Measurement:
    """Simulate ``model`` with ``effects`` injected and white noise (fraction of each channel's std).

    ``effects`` are spec strings or :class:`~suspid.effects.Effect` objects (e.g. an
    effect restricted to one strut of a half car); ``quarter2`` defaults to the seed's
    Table 1, the other models to their documented defaults; ``noise_seed=S`` draws the
    noise ``suspid simulate --seed S`` draws. See
    :func:`tools.synthetic_record.synthetic_record`.
    """
    p = dict(TABLE1) if params is None and model == "quarter2" else params
    return synthetic_record(model, effects, scenario, params=p, fs=fs, duration=duration,
                            noise=noise, seed=seed, extra_force=extra_force, noise_seed=noise_seed,
                            **scen)
