"""The node's plant: the core's suspension model (:func:`suspid.simulate.simulate`) stepped
in chunks, the state carried across them, parameters held constant within a chunk."""
from __future__ import annotations

import copy
from typing import Callable, Mapping, Sequence

import numpy as np

from suspid.models.base import FloatArray, ForceFn, SuspensionModel
from suspid.effects import Effect, Injection, inject
from suspid.simulate import simulate

ParamsFn = Callable[[float], Mapping[str, float]]


class Plant:
    """Suspension model driven by a precomputed road (m, m/s; may be empty), sampled at the
    uniform times ``t`` (s) from ``x0`` (``[q, q']``). ``params`` (SI) may be a function of
    time, constant within a ``chunk_s`` (s) chunk; ``extra_forces`` are added to a copy of
    the model; ``effects`` (:mod:`suspid.effects`) act on the plant or the sensors."""

    def __init__(self, model: SuspensionModel, params: Mapping[str, float] | ParamsFn,
                 t: FloatArray, road: Mapping[str, FloatArray] | None = None,
                 x0: FloatArray | None = None, chunk_s: float = 1.0,
                 extra_forces: Sequence[ForceFn] | None = None,
                 effects: Sequence[Effect | str | Mapping[str, object]] | None = None) -> None:
        self._physical: Injection | None = None
        self._sensor: Injection | None = None
        self._true_last: dict[str, FloatArray] | None = None
        self._prev: tuple[FloatArray, dict[str, FloatArray]] | None = None
        if effects:
            inj = inject(model, effects)  # validates names, parameters and channels
            inj.check_record(np.asarray(t, dtype=float))  # e.g. a delay longer than the run
            if inj.physical:
                self._physical = inject(model, inj.physical)
            if inj.sensor:
                self._sensor = inject(model, inj.sensor)
        if extra_forces:
            model = copy.copy(model)
            model.extra_force = list(model.extra_force) + list(extra_forces)
        self.model = model
        if callable(params):
            self._params: ParamsFn = params
        else:
            fixed = dict(params)
            self._params = lambda _t: fixed
        self.t = np.asarray(t, dtype=float)
        self.affine = model.affine(self._params(float(self.t[0]) if self.t.size else 0.0))
        self.road = {k: np.asarray(v, dtype=float) for k, v in (road or {}).items()}
        self.fs = 1.0 / float(self.t[1] - self.t[0]) if self.t.size > 1 else 1.0
        self.chunk = max(2, int(round(chunk_s * self.fs)))
        self.x = np.zeros(model.n_states) if x0 is None else np.asarray(x0, dtype=float).copy()
        self.channels: tuple[str, ...] = tuple(model.channels) + tuple(
            model.ride_height_channels) + tuple(
            c for r in model.roads for c in (r, f"{r}_dot") if r in self.road)
        self._start = -1   # first sample index of the cached chunk
        self._cols: dict[str, FloatArray] = {}

    def _compute(self, k: int) -> None:
        """Simulate the chunk starting at sample ``k`` (the state is at sample ``k``)."""
        end = min(self.t.size, k + self.chunk + 1)
        tt = self.t[k:end]
        road = {n: v[k:end] for n, v in self.road.items()}
        p = self._params(float(tt[0]))
        if tt.size < 2:
            out = simulate(self.model, p, np.array([tt[0], tt[0] + 1.0 / self.fs]),
                           {n: np.repeat(v, 2) for n, v in road.items()}, self.x,
                           affine=self.affine)
            out = {n: v[:1] for n, v in out.items()}
        elif self._physical is not None:
            out = self._physical.simulate(p, tt, road or None, self.x)
        else:
            out = simulate(self.model, p, tt, road or None, self.x, affine=self.affine)
        if self._sensor is not None:
            out = self._measure(self._sensor, tt, out)
        nq = len(self.model.coords)
        last = len(tt) - 1
        true = self._true_last
        src = true if true is not None else out
        self.x = np.array([src[c][last] for c in self.model.coords]
                          + [src[f"{c}_dot"][last] for c in self.model.coords][:nq])
        self._true_last = None
        self._cols = {c: out[c] for c in self.channels if c in out}
        self._start = k

    def _measure(self, sensor: Injection, tt: FloatArray,
                 out: dict[str, FloatArray]) -> dict[str, FloatArray]:
        """Apply the sensor effects with the previous chunk as history; keep the true states."""
        self._true_last = out
        if self._prev is not None:
            pt, pc = self._prev
            keep = pt < tt[0]
            t_all = np.concatenate([pt[keep], tt])
            cols = {c: np.concatenate([pc[c][keep], out[c]]) for c in out if c in pc}
            meas = sensor.measure(t_all, cols)
            n0 = int(keep.sum())
            res = {c: v[n0:] for c, v in meas.items()}
        else:
            res = sensor.measure(tt, out)
        self._prev = (tt, out)
        return {c: res.get(c, out[c]) for c in out}

    def sample(self, k: int) -> dict[str, float]:
        """Every channel at sample ``k`` (samples must be requested in increasing order)."""
        if self._start < 0 or not (self._start <= k < self._start + self.chunk):
            if self._start >= 0 and k != self._start + self.chunk:
                raise ValueError(f"plant samples must be taken in order: asked {k}, next chunk "
                                 f"starts at {self._start + self.chunk}")
            self._compute(k)
        i = k - self._start
        return {c: float(v[i]) for c, v in self._cols.items()}
