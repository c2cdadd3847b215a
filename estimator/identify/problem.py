"""The output-error identification problem for the linear models (fast path).

Given a :class:`~suspid.io.csvio.Measurement` and a model, :class:`OutputErrorProblem`
predicts the measured channels for a parameter vector and returns the residual. The
initial state is handled by *variable projection*: the response is linear in ``x0``, so
for every parameter vector the best ``x0`` follows from a small linear least-squares
problem (``x0="estimate"``); ``x0="rest"`` starts at equilibrium and an array fixes it.

Cost functions (the seed's two):

``sse``
    sum of squared differences of the measured *position* channels (all measured channels
    when no position is measured);
``frobenius``
    Frobenius norm of the measured-minus-simulated matrix over every measured channel.

Nelder–Mead only compares cost values, so the two differ by the channels they use (and by
the termination test), not by the square root.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from suspid.errors import UsageError
from suspid.io.csvio import Measurement
from suspid.models.base import FloatArray, SuspensionModel
from suspid.simulate import (free_coeffs_to_state, free_response_basis, modal_form, modal_powers,
                             modal_trajectory, road_matrix, simulate_states, uniform_step)

COSTS = ("sse", "frobenius")


@dataclass
class Prediction:
    """A model prediction on the measured channels."""

    Y: FloatArray  # (N, p) predicted channels
    x0: FloatArray  # initial state used (n,)
    residual: FloatArray  # (N, p) measured - predicted, NaN where missing


@dataclass
class OutputErrorProblem:
    """Residuals of a linear suspension model against a measurement.

    Parameters
    ----------
    model : SuspensionModel
    meas : Measurement
    cost : {"sse", "frobenius"}
    x0 : "estimate", "rest" or ndarray
        Initial-state handling (see module docstring).
    weights : mapping, optional
        Per-channel weights multiplying the residual (default 1: the seed's raw SI cost).
    """

    model: SuspensionModel
    meas: Measurement
    cost: str = "sse"
    x0: str | FloatArray = "estimate"
    weights: Mapping[str, float] | None = None
    channels: list[str] = field(init=False)
    warnings: list[str] = field(init=False, default_factory=list)

    def __post_init__(self) -> None:
        if self.cost not in COSTS:
            raise UsageError(f"unknown cost {self.cost!r}; expected one of {', '.join(COSTS)}")
        m = self.model
        measured = [c for c in m.channels if c in self.meas.measured]
        if not measured:
            raise UsageError(f"no measured channel of model {m.name} in {self.meas.source}")
        if self.cost == "sse":
            pos = [c for c in measured if c in m.coords]
            if pos:
                self.channels = pos
            else:
                self.channels = measured
                self.warnings.append("cost sse: no position channel measured; using "
                                     f"{', '.join(measured)} instead")
        else:
            self.channels = measured
        self.t = np.asarray(self.meas.t, dtype=float)
        self.U = road_matrix(m, self.t, self.meas.road)
        self.Ymeas = np.column_stack([self.meas.measured[c] for c in self.channels])
        self.mask = ~np.isnan(self.Ymeas)
        self.Ymeas0 = np.where(self.mask, self.Ymeas, 0.0)
        w = np.array([float((self.weights or {}).get(c, 1.0)) for c in self.channels])
        self.w = w
        self.h = uniform_step(self.t)
        self.n_obs = int(self.mask.sum())
        self._has_road = bool(np.any(self.U))
        data_ss = float(np.sum((self.Ymeas0 * w) ** 2))
        self.scale = data_ss if data_ss > 0 else 1.0
        nq = len(m.coords)
        idx = {c: i for i, c in enumerate(m.coords)}
        self._kind = []
        for c in self.channels:
            base = c.split("_")[0]
            order = 2 if c.endswith("_ddot") else (1 if c.endswith("_dot") else 0)
            self._kind.append((idx[base], order))
        self._nq = nq

    # ---- linear maps from states to channels --------------------------------------
    def _output_maps(self, A: FloatArray, B: FloatArray) -> tuple[FloatArray, FloatArray]:
        n = self.model.n_states
        nq = self._nq
        Cm = np.zeros((len(self.channels), n))
        Dm = np.zeros((len(self.channels), B.shape[1]))
        for j, (i, order) in enumerate(self._kind):
            if order == 0:
                Cm[j, i] = 1.0
            elif order == 1:
                Cm[j, nq + i] = 1.0
            else:
                Cm[j] = A[nq + i]
                Dm[j] = B[nq + i]
        return Cm, Dm

    def predict(self, p: Mapping[str, float]) -> Prediction:
        """Predict the measured channels for parameters ``p`` (with the best ``x0``)."""
        m = self.model
        n = m.n_states
        nr = len(m.roads)
        modal = modal_form(m, p)
        A, B = (modal.A, modal.B) if modal is not None else m.state_space(p)
        Cm, Dm = self._output_maps(A, B)
        fixed_x0 = None if isinstance(self.x0, str) else np.asarray(self.x0, dtype=float)
        base_x0 = np.zeros(n) if fixed_x0 is None else fixed_x0
        r = self.U[:, :nr]
        fast = modal is not None and self.h is not None
        P = None
        if fast:
            if self._has_road:
                W = modal_trajectory(modal, self.h, r, base_x0)
            else:
                P = modal_powers(modal, self.h, self.t.size)
                W = P * (modal.Vinv @ base_x0)[None, :]
            Y = modal.real_part(W, Cm) + r @ (Cm @ modal.Bv).T + self.U @ Dm.T
        else:
            X = simulate_states(m, p, self.t, self.U, base_x0, modal=modal)
            Y = X @ Cm.T + self.U @ Dm.T
        x0 = base_x0
        if isinstance(self.x0, str) and self.x0 == "estimate":
            if fast:
                G = free_response_basis(modal, self.h, self.t.size, Cm, P)
            else:
                G = self._free_basis_slow(Cm, p)
            R = ((self.Ymeas0 - Y) * self.w * self.mask).reshape(-1)
            Gm = (G * (self.w[None, :, None] * self.mask[:, :, None])).reshape(-1, G.shape[2])
            GtG = Gm.T @ Gm
            try:
                sol = np.linalg.solve(GtG, Gm.T @ R)
                if not np.all(np.isfinite(sol)) or np.linalg.cond(GtG) > 1e12:
                    raise np.linalg.LinAlgError
            except np.linalg.LinAlgError:
                sol, *_ = np.linalg.lstsq(Gm, R, rcond=1e-12)
            Y = Y + G.reshape(-1, G.shape[2]).dot(sol).reshape(Y.shape)
            x0 = free_coeffs_to_state(modal, sol) if fast else sol
        res = np.where(self.mask, self.Ymeas - Y, np.nan)
        return Prediction(Y=Y, x0=x0, residual=res)

    def _free_basis_slow(self, Cm: FloatArray, p: Mapping[str, float]) -> FloatArray:
        """Response of each channel to a unit initial state, shape (N, p, n) (general path)."""
        N = self.t.size
        n = self.model.n_states
        G = np.empty((N, len(self.channels), n))
        zeroU = np.zeros_like(self.U)
        for j in range(n):
            e = np.zeros(n)
            e[j] = 1.0
            G[:, :, j] = simulate_states(self.model, p, self.t, zeroU, e) @ Cm.T
        return G

    def residual_vector(self, p: Mapping[str, float]) -> FloatArray:
        """Weighted residuals of the observed samples, flattened (for Jacobians)."""
        r = self.predict(p).residual * self.w
        return r[self.mask]

    def normalized_ss(self, p: Mapping[str, float]) -> float:
        """Weighted sum of squares divided by the data's (dimensionless, 1 = no fit)."""
        try:
            r = self.residual_vector(p)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            return np.inf
        v = float(r @ r) / self.scale
        return v if np.isfinite(v) else np.inf

    def seed_cost(self, ss: float) -> float:
        """Report the seed's cost from the raw weighted sum of squares ``ss``."""
        return float(np.sqrt(ss)) if self.cost == "frobenius" else float(ss)

    def rms_by_channel(self, res: FloatArray) -> dict[str, float]:
        """RMS residual per channel (SI)."""
        return {c: float(np.sqrt(np.nanmean(res[:, j] ** 2))) for j, c in enumerate(self.channels)}
