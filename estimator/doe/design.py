"""The seed's designs of experiments as concrete identification problems.

Each Taguchi row becomes an :class:`Experiment`: the true parameters, the known initial
state and the time grid of the noise-free target curve. What the seed leaves out is fixed
here and reported by :func:`setup_record` (it goes into ``suspid doe --json``):

* **Excitation**: the seed's DoE factors are initial states only, so every experiment is a
  free response from a known initial state (no road input), as in its Table 2 / §6.1.
* **Horizon and sample rate**: ``HORIZON`` = 20 s at ``FS`` = 100 Hz for every model. The
  designs span damping time constants from ~20 ms (``c1/m1`` = 100 1/s) to ~50 s and
  periods up to ~30 s (1-DOF, m = 2500 kg, k = 100 N/m); 20 s shows at least two thirds
  of the slowest period and 100 Hz resolves the fastest decay over a few samples. The
  simulation is exact at any sample rate (modal FOH), so the rate only sets how much
  information each record holds, not its accuracy.
* **Measured channels**: positions and velocities of every coordinate (the state matrix
  MATLAB's ode45 returns); cost ``sse`` uses the positions, ``frobenius`` all of them.
* **Half car** (seed §6.1): Table 5's columns map onto the half car *by name*: E, F, G
  (``m1``, ``c1``, ``k1``) are the front wheel mass, front damper and front spring; H, J,
  K (``m2``, ``c2``, ``k2``) the rear ones; A-D (``x01``, ``v01``, ``x02``, ``v02``) the
  initial position and velocity of the front (``x1``) and rear (``x2``) wheels. The body
  starts at x = 0.05 m, x' = 0.05 m/s, delta = 0.05 rad, delta' = 0.05 rad/s; targets
  a1 = 0.48 m, a2 = 0.52 m, k3 = 1000 N/m, k4 = 500 N/m (all identified, not fixed).
  The seed gives no body mass or pitch inertia: ``m`` = 200 kg (a half car carries two
  corners, each up to Table 5's top sprung-mass level of 100 kg) and ``I`` = 40 kg m^2
  (radius of gyration 0.447 m, dynamic index I / (m a1 a2) = 0.80, typical of passenger
  cars; an index of exactly 1 would make the front and rear dynamically independent, a
  special case we avoid).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from estimator.doe.arrays import L16_ARRAY, L16_LEVELS, L27_ARRAY, L27_LEVELS
from suspid.errors import UsageError
from suspid.models import SuspensionModel, get_model
from suspid.models.base import FloatArray

#: record length (s) of every target curve
HORIZON = 20.0
#: sample rate (Hz) of every target curve
FS = 100.0
#: seed §6.1 half-car constants (targets, identified) and our choices for m, I
HALF4_CONSTANTS: dict[str, float] = {"a1": 0.48, "a2": 0.52, "k3": 1000.0, "k4": 500.0,
                                     "m": 200.0, "I": 40.0}
#: seed §6.1 body initial state [x (m), delta (rad), x' (m/s), delta' (rad/s)]
HALF4_BODY_X0: dict[str, float] = {"x": 0.05, "delta": 0.05, "x_dot": 0.05, "delta_dot": 0.05}
#: Table 5 column -> half4 initial-state name or parameter (mapping by name)
HALF4_COLUMNS: dict[str, str] = {"A": "x1", "B": "x1_dot", "C": "x2", "D": "x2_dot",
                                 "E": "m1", "F": "c1", "G": "k1", "H": "m2", "J": "c2", "K": "k2"}
#: Table 5 column -> quarter2 initial-state name or parameter
QUARTER2_COLUMNS: dict[str, str] = {"A": "x1", "B": "x1_dot", "C": "x2", "D": "x2_dot",
                                    "E": "m1", "F": "c1", "G": "k1", "H": "m2", "J": "c2", "K": "k2"}
#: Table 3 column -> quarter1 initial-state name or parameter
QUARTER1_COLUMNS: dict[str, str] = {"A": "x", "B": "x_dot", "C": "m", "D": "c", "E": "k"}

@dataclass(frozen=True)
class DesignSpec:
    """One model's seed design: the orthogonal array, its factor levels, the column map.

    Attributes
    ----------
    name : str
        The design's name (``L16-4``, ``L27-3``).
    array : ndarray
        Rows of factor levels (1-based).
    levels : dict
        Factor letter -> (name, unit, level values).
    columns : dict
        Factor letter -> the model's parameter or initial-state name.
    constants : dict
        Further true parameter values every row shares (SI).
    body_x0 : dict
        Further initial-state values every row shares.
    choices : dict
        The design choices the seed leaves out, with their reasons (for ``setup_record``).
    """

    name: str
    array: Any
    levels: dict[str, Any]
    columns: dict[str, str]
    constants: dict[str, float] = field(default_factory=dict)
    body_x0: dict[str, float] = field(default_factory=dict)
    choices: dict[str, str] = field(default_factory=dict)


#: seed §6.1 half car: what the seed leaves out, and why
HALF4_CHOICES: dict[str, str] = {
    "column_mapping": "Table 5 by name: E,F,G = front wheel mass m1, front damper c1, "
                      "front spring k1; H,J,K = rear m2, c2, k2; A-D = front/rear wheel "
                      "initial position and velocity",
    "m": "200 kg: two corners at Table 5's top sprung-mass level (100 kg each)",
    "I": "40 kg m^2: dynamic index I/(m a1 a2) = 0.80 (typical car; 1 would make "
         "front and rear dynamically independent)",
    "horizon_s": "20 s: >= 2/3 of the slowest period of every design row",
    "sample_rate_hz": "100 Hz: resolves the fastest decay (~42 1/s) over several samples",
}


#: the registry of designs, by model name (the one place that names the models)
DESIGN_SPECS: dict[str, DesignSpec] = {
    "quarter1": DesignSpec("L16-4", L16_ARRAY, L16_LEVELS, QUARTER1_COLUMNS),
    "quarter2": DesignSpec("L27-3", L27_ARRAY, L27_LEVELS, QUARTER2_COLUMNS),
    "half4": DesignSpec("L27-3", L27_ARRAY, L27_LEVELS, HALF4_COLUMNS, HALF4_CONSTANTS,
                        HALF4_BODY_X0, HALF4_CHOICES),
}
DESIGNS: dict[str, str] = {k: v.name for k, v in DESIGN_SPECS.items()}


@dataclass
class Experiment:
    """One row of a design: the truth and the known initial state.

    Attributes
    ----------
    id : int
        Row number as in the seed's Table 4 / 6 (1-based).
    levels : dict
        Factor letter -> level (1-based).
    truth : dict
        Every model parameter (SI units).
    x0 : ndarray
        Initial state ``[q..., q'...]`` (m, rad, m/s, rad/s).
    """

    id: int
    levels: dict[str, int]
    truth: dict[str, float]
    x0: FloatArray = field(repr=False)


def design_spec(model: SuspensionModel) -> DesignSpec:
    """The seed design registered for ``model`` (UsageError naming the known ones if none)."""
    try:
        return DESIGN_SPECS[model.name]
    except KeyError:
        raise UsageError(f"no design for model {model.name!r}; "
                         f"expected one of {', '.join(DESIGN_SPECS)}") from None


def experiments(model: SuspensionModel | str) -> list[Experiment]:
    """All experiments of the seed's design for ``model`` in the seed's order.

    Parameters
    ----------
    model : SuspensionModel or str
        ``quarter1`` (L16-4, Tables 3-4), ``quarter2`` or ``half4`` (L27-3, Tables 5-6).
    """
    if isinstance(model, str):
        model = get_model(model)
    spec = design_spec(model)
    array, levels, cols = spec.array, spec.levels, spec.columns
    letters = list(levels)
    states = {s: i for i, s in enumerate(model.state_names)}
    out = []
    for row_id, row in enumerate(array, start=1):
        truth: dict[str, float] = {}
        x0 = np.zeros(model.n_states)
        truth.update(spec.constants)
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
    name = model if isinstance(model, str) else model.name
    m = get_model(name)
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
    if spec.constants:
        rec["constants"] = dict(spec.constants)
    if spec.body_x0:
        rec["body_initial_state"] = dict(spec.body_x0)
    if spec.choices:
        rec["choices"] = dict(spec.choices)
    return rec
