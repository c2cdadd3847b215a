"""The seed's designs of experiments as concrete identification problems.

Each Taguchi row becomes an :class:`Experiment` (truth, known initial state, free response on
the grid of ``HORIZON`` s at ``FS`` Hz, see ``docs/paper-reproduction.md``); the array and
factor map belong to the model (:attr:`~suspid.models.base.SuspensionModel.doe_design`).
"""
from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from estimator.doe.arrays import L16_ARRAY, L16_LEVELS, L27_ARRAY, L27_LEVELS
from suspid.errors import UsageError
from suspid.models import MODELS, SuspensionModel, get_model
from suspid.models.base import FloatArray

#: record length (s) of every target curve
HORIZON = 20.0
#: sample rate (Hz) of every target curve
FS = 100.0
#: the seed's orthogonal arrays by name: (rows, factor letter -> (name, unit, levels))
SEED_ARRAYS: dict[str, tuple[Any, dict[str, Any]]] = {
    "L16-4": (L16_ARRAY, L16_LEVELS),
    "L27-3": (L27_ARRAY, L27_LEVELS),
}


@dataclass(frozen=True)
class DesignSpec:
    """One model's design resolved: array, factor ``levels`` (name, unit, values), ``columns`` (factor ->
    parameter or state), shared ``constants`` and ``body_x0`` (SI) and the seed's missing ``choices``.
    """

    name: str
    array: Any
    levels: dict[str, Any]
    columns: dict[str, str]
    constants: dict[str, float] = field(default_factory=dict)
    body_x0: dict[str, float] = field(default_factory=dict)
    choices: dict[str, str] = field(default_factory=dict)


def design_spec(model: SuspensionModel) -> DesignSpec:
    """The design ``model`` declares; UsageError when it has none or it does not fit the model."""
    d = model.doe_design
    if d is None:
        raise UsageError(f"no design for model {model.name!r}; "
                         f"expected one of {', '.join(DESIGNS)}")
    if d.rows is not None and d.levels is not None:
        rows: Any = np.asarray(d.rows, dtype=np.int64)
        all_levels: Mapping[str, Any] = d.levels
    elif d.array in SEED_ARRAYS:
        rows, all_levels = SEED_ARRAYS[d.array]
    else:
        raise UsageError(f"model {model.name}: design array {d.array!r} is not one of the seed's "
                         f"({', '.join(SEED_ARRAYS)}) and the model gives no rows and levels")
    letters = list(all_levels)
    targets = set(model.param_names) | set(model.state_names)
    bad = [f"{k} -> {v}" for k, v in d.columns.items() if k not in all_levels or v not in targets]
    if bad:
        raise UsageError(f"model {model.name}: design {d.array} maps {', '.join(bad)}; expected "
                         f"factors {', '.join(letters)} onto its parameters or states")
    bad = [k for k in list(d.body_x0) if k not in model.state_names]
    bad += [k for k in list(d.constants) if k not in model.param_names]
    if bad:
        raise UsageError(f"model {model.name}: design {d.array} sets {', '.join(bad)}, which "
                         f"are not its parameters or states")
    missing = [k for k in model.param_names if k not in d.constants and k not in d.columns.values()]
    if missing:
        raise UsageError(f"model {model.name}: design {d.array} gives no value to "
                         f"{', '.join(missing)}")
    used = [j for j, k in enumerate(letters) if k in d.columns]
    return DesignSpec(d.array, rows[:, used], {k: all_levels[k] for k in letters if k in d.columns},
                      {k: d.columns[k] for k in letters if k in d.columns}, dict(d.constants),
                      dict(d.body_x0), dict(d.choices))


class _Designs(Mapping[str, str]):
    """``model name -> design name`` of every model with a design."""

    def _names(self) -> list[str]:
        out = []
        for name in MODELS:
            try:
                if get_model(name).doe_design is not None:
                    out.append(name)
            except UsageError:  # a broken plug-in has no design to offer
                continue
        return out

    def __getitem__(self, name: str) -> str:
        model = get_model(name) if name in MODELS else None
        if model is None or model.doe_design is None:
            raise KeyError(name)
        return design_spec(model).name

    def __iter__(self) -> Iterator[str]:
        return iter(self._names())

    def __len__(self) -> int:
        return len(self._names())


#: the design's name of every model that has one (``suspid doe --model`` choices; read from the models)
DESIGNS: Mapping[str, str] = _Designs()


@dataclass
class Experiment:
    """One row of a design: ``id`` (1-based, as in the seed), factor ``levels``, ``truth`` (SI), ``x0``."""

    id: int
    levels: dict[str, int]
    truth: dict[str, float]
    x0: FloatArray = field(repr=False)


def experiments(model: SuspensionModel | str) -> list[Experiment]:
    """All experiments of the seed's design for ``model`` in the seed's order."""
    if isinstance(model, str):
        model = get_model(model)
    spec = design_spec(model)
    array, levels, cols = spec.array, spec.levels, spec.columns
    letters = list(levels)
    states = {s: i for i, s in enumerate(model.state_names)}
    out = []
    for row_id, row in enumerate(array, start=1):
        truth = dict(spec.constants)
        x0 = np.zeros(model.n_states)
        for s, v in spec.body_x0.items():
            x0[states[s]] = v
        lv = {}
        for j, letter in enumerate(letters):
            value = float(levels[letter][2][int(row[j]) - 1])
            lv[letter] = int(row[j])
            target = cols[letter]
            if target in states:
                x0[states[target]] = value
            else:
                truth[target] = value
        ordered = {n: truth[n] for n in model.param_names}
        out.append(Experiment(row_id, lv, ordered, x0))
    return out


def time_grid(horizon: float = HORIZON, fs: float = FS) -> FloatArray:
    """Sample times ``0, 1/fs, ..., horizon`` (s)."""
    return np.arange(int(round(horizon * fs)) + 1) / fs


def setup_record(model: SuspensionModel | str, horizon: float = HORIZON,
                 fs: float = FS) -> dict[str, Any]:
    """The design choices the seed leaves out, as a JSON-ready dict."""
    m = get_model(model) if isinstance(model, str) else model
    spec = design_spec(m)
    levels, cols = spec.levels, spec.columns
    rec: dict[str, Any] = {
        "excitation": "free response from the design's known initial state (no road input)",
        "horizon_s": horizon,
        "sample_rate_hz": fs,
        "samples": int(round(horizon * fs)) + 1,
        "measured": list(m.state_names),
        "cost_channels": {"sse": list(m.coords), "frobenius": list(m.state_names)},
        "initial_state": "known (the design's values); not estimated",
        "column_mapping": {k: f"{levels[k][0]} -> {v}" for k, v in cols.items()},
        "simulation": "exact modal solution (suspid.simulate), not ode45",
    }
    for key, value in (("constants", spec.constants), ("body_initial_state", spec.body_x0),
                       ("choices", spec.choices)):
        if value:
            rec[key] = dict(value)
    return rec
