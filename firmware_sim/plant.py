"""The node's plant: the core's suspension model, stepped in chunks.

The physics stays in :mod:`suspid.models` / :mod:`suspid.simulate`: the plant asks
:func:`suspid.simulate.simulate` for one chunk of samples at a time (exact for the linear
models; the ODE path when the model has ``extra_force`` terms) and carries the state
``[q, q']`` across chunk boundaries. Parameters may change with time (damper wear): they
are evaluated once per chunk, i.e. held piecewise constant over ``chunk_s``.

Undeclared effects for the diagnosis work (issue 6) go in through the model: pass a model
whose ``extra_force`` list holds the extra generalised forces, or ``extra_forces=[...]``
here (appended to a copy of the model's list).
"""
from __future__ import annotations

import copy
from typing import Callable, Mapping, Sequence

import numpy as np

from suspid.models.base import FloatArray, ForceFn, SuspensionModel
from suspid.simulate import simulate

ParamsFn = Callable[[float], Mapping[str, float]]


class Plant:
    """Suspension model driven by a precomputed road, sampled on a uniform grid.

    Parameters
    ----------
    model : SuspensionModel
    params : mapping or callable
        Parameters (SI), or ``params(t) -> mapping`` for time-varying ones.
    t : ndarray, shape (N,)
        Sample times (s), uniform.
    road : dict
        Road arrays (m, m/s) of length N (may be empty: no road input).
    x0 : ndarray, optional
        Initial state ``[q, q']``.
    chunk_s : float
        Simulation chunk length (s); parameters are constant within a chunk.
    extra_forces : sequence of callables, optional
        Added to the model's ``extra_force`` (on a copy of the model).

    Attributes
    ----------
    channels : tuple of str
        Channels :meth:`sample` returns (model channels and road columns).
    """

    def __init__(self, model: SuspensionModel, params: Mapping[str, float] | ParamsFn,
                 t: FloatArray, road: Mapping[str, FloatArray] | None = None,
                 x0: FloatArray | None = None, chunk_s: float = 1.0,
                 extra_forces: Sequence[ForceFn] | None = None) -> None:
        if extra_forces:
            model = copy.copy(model)
            model.extra_force = list(model.extra_force) + list(extra_forces)
        self.model = model
        self._params: ParamsFn = params if callable(params) else (lambda _t, p=dict(params): p)
        self.t = np.asarray(t, dtype=float)
        self.road = {k: np.asarray(v, dtype=float) for k, v in (road or {}).items()}
        self.fs = 1.0 / float(self.t[1] - self.t[0]) if self.t.size > 1 else 1.0
        self.chunk = max(2, int(round(chunk_s * self.fs)))
        self.x = np.zeros(model.n_states) if x0 is None else np.asarray(x0, dtype=float).copy()
        self.channels: tuple[str, ...] = tuple(model.channels) + tuple(
            c for r in model.roads for c in (r, f"{r}_dot") if r in self.road)
        self._start = -1   # first sample index of the cached chunk
        self._cols: dict[str, FloatArray] = {}

    def params_at(self, t: float) -> Mapping[str, float]:
        """Parameters (SI) in force at time ``t`` (s)."""
        return self._params(t)

    def _compute(self, k: int) -> None:
        """Simulate the chunk starting at sample ``k`` (the state is at sample ``k``)."""
        end = min(self.t.size, k + self.chunk + 1)
        tt = self.t[k:end]
        road = {n: v[k:end] for n, v in self.road.items()}
        p = self._params(float(tt[0]))
        if tt.size < 2:
            out = simulate(self.model, p, np.array([tt[0], tt[0] + 1.0 / self.fs]),
                           {n: np.repeat(v, 2) for n, v in road.items()}, self.x)
            out = {n: v[:1] for n, v in out.items()}
        else:
            out = simulate(self.model, p, tt, road or None, self.x)
        nq = len(self.model.coords)
        last = len(tt) - 1
        self.x = np.array([out[c][last] for c in self.model.coords]
                          + [out[f"{c}_dot"][last] for c in self.model.coords][:nq])
        self._cols = {c: out[c] for c in self.channels if c in out}
        self._start = k

    def sample(self, k: int) -> dict[str, float]:
        """Every channel at sample ``k`` (samples must be requested in increasing order)."""
        if self._start < 0 or not (self._start <= k < self._start + self.chunk):
            if self._start >= 0 and k != self._start + self.chunk:
                raise ValueError(f"plant samples must be taken in order: asked {k}, next chunk "
                                 f"starts at {self._start + self.chunk}")
            self._compute(k)
        i = k - self._start
        return {c: float(v[i]) for c, v in self._cols.items()}
