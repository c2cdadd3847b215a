"""The output-error identification problem for the linear models (fast path).

Given a :class:`~suspid.io.csvio.Measurement` and a model, :class:`OutputErrorProblem`
predicts the measured channels for a parameter vector and returns the residual. The
initial state is handled by *variable projection*: the response is linear in ``x0``, so
for every parameter vector the best ``x0`` follows from a small linear least-squares
problem (``x0="estimate"``); ``x0="rest"`` starts at equilibrium and an array fixes it.

Cost functions (the seed's two):

``sse``
    sum of squared differences of the measured *position* channels, ride heights included
    (all measured channels when no position is measured);
``frobenius``
    Frobenius norm of the measured-minus-simulated matrix over every measured channel.

Nelder–Mead only compares cost values, so the two differ by the channels they use (and by
the termination test), not by the square root.

Ride heights (``d``/``dN`` and their ``_dot``: strut extensions) are compared like the
motions: strut ``i``'s extension is ``g . q + gr . r`` (its rate with ``q'``, ``r'``) on the
problem's road input (the record's road, or none), rows of the output map after those of the
motion channels (:func:`ride_height_rows`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Mapping, Sequence

import numpy as np

from estimator.choices import COSTS
from suspid.errors import InputError, UsageError
from suspid.io.csvio import Measurement
from suspid.models.base import AffinePieces, FloatArray, SuspensionModel
from suspid.simulate import (Modal, free_coeffs_to_state, free_response_basis, modal_form,
                             modal_step_powers, modal_trajectory, mode_pattern, powers,
                             ride_height_maps, road_matrix, simulate_states, state_matrices,
                             uniform_step)

#: most modal powers (points x samples x modes) one stacked evaluation holds (~0.8 MB)
_STACK_ENTRIES = 50000
#: most points one stacked evaluation holds: beyond 4 the per-point time rose again on a
#: shared two-core machine (docs/performance.md)
_STACK_POINTS = 4


@dataclass
class Prediction:
    """A model prediction on the measured channels."""

    Y: FloatArray  # (N, p) predicted channels
    x0: FloatArray  # initial state used (n,)
    residual: FloatArray  # (N, p) measured - predicted, NaN where missing


def channel_kinds(coords: Sequence[str], channels: Sequence[str]) -> list[tuple[int, int]]:
    """``(coordinate index, derivative order)`` of each channel name (``x1_dot`` -> (i, 1))."""
    idx = {c: i for i, c in enumerate(coords)}
    return [(idx[c.split("_")[0]], 2 if c.endswith("_ddot") else (1 if c.endswith("_dot") else 0))
            for c in channels]


def output_maps(kinds: Sequence[tuple[int, int]], A: FloatArray, B: FloatArray, nq: int
                ) -> tuple[FloatArray, FloatArray]:
    """Output maps ``y = Cm x + Dm u`` of channels given by :func:`channel_kinds`.

    Positions and velocities are rows of the identity on the state ``x = [q, q']``;
    an acceleration is the model's row ``q'' = A[nq + i] x + B[nq + i] u``.
    """
    Cm = np.zeros((len(kinds), A.shape[0]))
    Dm = np.zeros((len(kinds), B.shape[1]))
    for j, (i, order) in enumerate(kinds):
        if order == 0:
            Cm[j, i] = 1.0
        elif order == 1:
            Cm[j, nq + i] = 1.0
        else:
            Cm[j] = A[nq + i]
            Dm[j] = B[nq + i]
    return Cm, Dm


def ride_height_rows(model: SuspensionModel, channels: Sequence[str], p: Mapping[str, float]
                     ) -> tuple[FloatArray, FloatArray]:
    """Output maps ``y = C x + D u`` of ride-height channels (``d``, ``d2_dot``, ...).

    A strut's extension ``g . q + gr . r`` (m) reads the positions and the roads, its rate
    ``g . q' + gr . r'`` (m/s) the velocities and the road rates (``g``, ``gr`` of
    ``model.strut_sites(p)``, so the geometry in ``p`` counts).

    Returns
    -------
    C : ndarray, shape (len(channels), n_states)
    D : ndarray, shape (len(channels), 2 n_roads)
    """
    G, Gr = ride_height_maps(model, p)
    nq, nr = G.shape[1], Gr.shape[1]
    index = {d: i for i, d in enumerate(model.ride_heights)}
    C = np.zeros((len(channels), 2 * nq))
    D = np.zeros((len(channels), 2 * nr))
    for j, c in enumerate(channels):
        rate = c.endswith("_dot")
        i = index[c[:-4] if rate else c]
        C[j, nq * rate:nq * (rate + 1)] = G[i]
        D[j, nr * rate:nr * (rate + 1)] = Gr[i]
    return C, D


def check_magnitudes(source: str, columns: Mapping[str, FloatArray]) -> None:
    """Raise :class:`~suspid.errors.InputError` naming the first column whose sum of squares
    overflows (values near 1e200 and up, a unit slip): no cost can be formed on it.

    Parameters
    ----------
    source : str
        Where the record came from (for the message).
    columns : mapping
        Column name -> values (NaN for missing samples are skipped).
    """
    for name, col in columns.items():
        c = np.nan_to_num(np.asarray(col, dtype=float), nan=0.0)
        with np.errstate(over="ignore"):
            ok = np.isfinite(float(c @ c))
        if not ok:
            big = float(np.max(np.abs(c)))
            raise InputError(f"{source}: column {name!r}: values up to {big:.3g} "
                             "overflow the sum of squares; expected SI units (m, m/s, m/s^2, rad)")


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
    affine : AffinePieces, optional
        The model's forward model as affine pieces
        (:meth:`~suspid.models.base.SuspensionModel.affine`); default: built from the first
        predicted parameter set with every damper and spring free. A parameter set they do
        not apply to (another mass, inertia or length) is predicted from the model itself.
    """

    model: SuspensionModel
    meas: Measurement
    cost: str = "sse"
    x0: str | FloatArray = "estimate"
    weights: Mapping[str, float] | None = None
    affine: AffinePieces | None = None
    channels: list[str] = field(init=False)
    warnings: list[str] = field(init=False, default_factory=list)
    #: whether measured ride heights enter the cost (a subclass with its own output path
    #: that does not map them sets ``False``: they are then left out with a warning)
    compares_ride_heights: ClassVar[bool] = True

    def __post_init__(self) -> None:
        if self.cost not in COSTS:
            raise UsageError(f"unknown cost {self.cost!r}; expected one of {', '.join(COSTS)}")
        m = self.model
        motions = [c for c in m.channels if c in self.meas.measured]
        heights = [c for c in m.ride_height_channels if c in self.meas.measured]
        if heights and not self.compares_ride_heights:
            self.warnings.append(f"ride-height channel(s) {', '.join(heights)} not compared "
                                 f"({type(self).__name__} fits the motion channels only)")
            heights = []
        measured = motions + heights
        if not measured:
            raise UsageError(f"no measured channel of model {m.name} in {self.meas.source}")
        if self.cost == "sse":
            pos = [c for c in measured if c in m.coords or c in m.ride_heights]
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
        self._check_magnitudes()
        self.h = uniform_step(self.t)
        self.n_obs = int(self.mask.sum())
        self._full = bool(self.mask.all())
        self._unit_w = bool(np.all(w == 1.0))
        self._has_road = bool(np.any(self.U))
        data_ss = float(np.sum((self.Ymeas0 * w) ** 2))
        self.scale = data_ss if data_ss > 0 else 1.0
        self._heights = [c for c in self.channels if c in m.ride_height_channels]
        self._kind = channel_kinds(m.coords, self.channels[:len(self.channels) - len(self._heights)])
        self._nq = len(m.coords)
        # ride-height rows of the output maps, for the geometry they were built with
        self._rh_geom: tuple[float, ...] | None = None
        self._rh_maps = (np.zeros((0, m.n_states)), np.zeros((0, 2 * len(m.roads))))
        if self._heights:
            self._set_heights(m.defaults())
        # what depends on the data alone, not on the parameters (the hot path's constants)
        self._estimate = isinstance(self.x0, str) and self.x0 == "estimate"
        self._x0_base = (np.zeros(m.n_states) if isinstance(self.x0, str)
                         else np.asarray(self.x0, dtype=float))
        self._x0_nonzero = bool(np.any(self._x0_base))
        # with no acceleration channel the output maps do not depend on the parameters
        self._maps_fixed: tuple[FloatArray, FloatArray] | None = None
        if all(order < 2 for _, order in self._kind):
            self._maps_fixed = self._stack_heights(output_maps(
                self._kind, np.zeros((m.n_states, m.n_states)),
                np.zeros((m.n_states, 2 * len(m.roads))), self._nq))
        self._w2 = w ** 2
        # weights and mask as flat (N p,) rows: an elementwise product with a broadcast
        # (p,) row runs one short inner loop per sample, 3-4x slower
        self._w_flat = np.tile(w, self.t.size)
        self._mask_flat = self.mask.reshape(-1)

    def _check_magnitudes(self) -> None:
        """Raise :class:`~suspid.errors.InputError` naming a measured or road column whose
        sum of squares overflows (see :func:`check_magnitudes`)."""
        nr = len(self.model.roads)
        names = list(self.channels) + list(self.model.roads) + [f"{r}_dot" for r in self.model.roads]
        cols = np.column_stack([self.Ymeas0, self.U[:, :nr], self.U[:, nr:]])
        check_magnitudes(self.meas.source, dict(zip(names, cols.T)))

    # ---- linear maps from states to channels --------------------------------------
    def _output_maps(self, A: FloatArray, B: FloatArray) -> tuple[FloatArray, FloatArray]:
        if self._maps_fixed is not None:
            return self._maps_fixed
        return self._stack_heights(output_maps(self._kind, A, B, self._nq))

    def _stack_heights(self, maps: tuple[FloatArray, FloatArray]) -> tuple[FloatArray, FloatArray]:
        """The motion channels' maps with the ride heights' rows below them."""
        if not self._heights:
            return maps
        return np.vstack([maps[0], self._rh_maps[0]]), np.vstack([maps[1], self._rh_maps[1]])

    def _geometry(self, p: Mapping[str, float]) -> tuple[float, ...]:
        """What the ride heights' rows depend on: the struts' directions for ``p``."""
        G, Gr = ride_height_maps(self.model, p)
        return tuple(G.ravel().tolist() + Gr.ravel().tolist())

    def _set_heights(self, p: Mapping[str, float]) -> None:
        """Build the ride heights' output rows for the geometry of ``p`` (when it changed)."""
        if not self._heights:
            return
        geom = self._geometry(p)
        if geom == self._rh_geom:
            return
        self._rh_geom = geom
        self._rh_maps = ride_height_rows(self.model, self._heights, p)
        if getattr(self, "_maps_fixed", None) is not None:
            m = self.model
            self._maps_fixed = self._stack_heights(output_maps(
                self._kind, np.zeros((m.n_states, m.n_states)),
                np.zeros((m.n_states, 2 * len(m.roads))), self._nq))

    def measured_coords(self) -> set[str]:
        """The coordinates the cost's channels observe: those of its motion channels and
        every coordinate a compared ride height reads (a strut's body and wheel)."""
        m = self.model
        seen = {m.coords[i] for i, _ in self._kind}
        if self._heights:
            G, _ = ride_height_maps(m, m.defaults())
            index = {d: i for i, d in enumerate(m.ride_heights)}
            for c in self._heights:
                row = G[index[c[:-4] if c.endswith("_dot") else c]]
                seen |= {m.coords[j] for j in np.flatnonzero(row)}
        return seen

    @property
    def is_estimating_x0(self) -> bool:
        """Whether the fit estimates the initial state (``x0="estimate"``): one unknown
        per state besides the parameters."""
        return bool(self._estimate)

    def pieces(self, p: Mapping[str, float]) -> AffinePieces | None:
        """The forward model's affine pieces (built from the first finite ``p``)."""
        if self.affine is None and all(np.isfinite(v) for v in p.values()):
            self.affine = self.model.affine(p)
        return self.affine

    def predict(self, p: Mapping[str, float]) -> Prediction:
        """Predict the measured channels for parameters ``p`` (with the best ``x0``)."""
        m = self.model
        self._set_heights(p)
        aff = self.pieces(p)
        modal = modal_form(m, p, aff)
        if modal is not None and self.h is not None:
            Y, x0 = self._predict_modal(modal, self.h)
        else:
            Y, x0 = self._predict_general(p, modal, aff)
        if self._full:
            res = self.Ymeas - Y
        else:
            res = np.where(self.mask, self.Ymeas - Y, np.nan)
        return Prediction(Y=Y, x0=x0, residual=res)

    def _base_x0(self) -> FloatArray:
        if isinstance(self.x0, str):
            return np.zeros(self.model.n_states)
        return np.asarray(self.x0, dtype=float)

    def _predict_modal(self, modal: Modal, h: float) -> tuple[FloatArray, FloatArray]:
        """Fast path (uniform grid, diagonalisable ``A``): modal recursion.

        With ``x0="estimate"`` and no missing sample the normal equations of the initial
        state are formed in closed form: the Gram matrix of the free-response regressors
        is a sum of geometric series in the products of the modes' ``exp(lam h)``, so no
        ``(N, p, n)`` regressor array is built.
        """
        m = self.model
        N = self.t.size
        h = float(h)
        Cm, Dm = self._output_maps(modal.A, modal.B)
        CV = (Cm @ modal.V) * modal.fac  # (p, mm)
        estimate = self._estimate
        base_x0 = self._x0_base
        E = np.exp(modal.lam * h)
        P: np.ndarray | None = None  # powers of E, built once and only where needed
        Y: FloatArray | None = None  # None: the zero response (no road, x0 at rest)
        if self._has_road:
            nr = len(m.roads)
            r = self.U[:, :nr]
            W = modal_trajectory(modal, h, r, base_x0)
            Y = _re_dot(W, CV.T) + r @ (Cm @ modal.Bv).T + self.U @ Dm.T
        elif self._x0_nonzero:
            P = powers(E, N)
            Y = _re_dot(P, (CV * (modal.Vinv @ base_x0)).T)
        if not estimate:
            return (Y if Y is not None else np.zeros((N, len(self.channels)))), base_x0
        if P is None:
            P = powers(E, N)
        if self._full:
            sol = self._x0_closed_form(modal, CV, E, P, Y)
            if sol is not None:
                mm = modal.lam.size
                pairs = modal.fac == 2.0
                c = sol[:mm].astype(complex)
                c[pairs] += 1j * sol[mm:]
                Yx = _re_dot(P, (CV * c).T)
                # adding the zero response changes no value (0.0 + y == y)
                return (Yx if Y is None else Y + Yx), free_coeffs_to_state(modal, sol)
        if Y is None:
            Y = np.zeros((N, len(self.channels)))
        G = free_response_basis(modal, h, N, Cm, P)
        sol = self._solve_x0(G, Y)
        Y = Y + G.reshape(-1, G.shape[2]).dot(sol).reshape(Y.shape)
        return Y, free_coeffs_to_state(modal, sol)

    def _x0_closed_form(self, modal: Modal, CV: np.ndarray, E: np.ndarray, P: np.ndarray,
                        Y: FloatArray | None) -> FloatArray | None:
        """Least-squares modal initial coefficients from closed-form normal equations.

        ``Y`` is the response without the free part (``None``: zero). Returns ``None`` when
        the Gram matrix is singular or ill-conditioned (the caller then solves the explicit
        least-squares problem).
        """
        sol = self._x0_closed_form_stack(modal.fac, CV[None], E[None], P[None],
                                         None if Y is None else Y[None])
        return None if sol is None else sol[0]

    def _solve_x0(self, G: FloatArray, Y: FloatArray) -> FloatArray:
        """Explicit weighted least squares for the free-response coefficients.

        NaN coefficients (so a non-finite residual and cost) when the response overflows:
        parameters far from any physical value on a long record.
        """
        R = ((self.Ymeas0 - Y) * self.w * self.mask).reshape(-1)
        Gm = (G * (self.w[None, :, None] * self.mask[:, :, None])).reshape(-1, G.shape[2])
        if not (np.isfinite(R).all() and np.isfinite(Gm).all()):
            return np.full(G.shape[2], np.nan)
        GtG = Gm.T @ Gm
        try:
            sol = np.linalg.solve(GtG, Gm.T @ R)
            if not np.all(np.isfinite(sol)) or np.linalg.cond(GtG) > 1e12:
                raise np.linalg.LinAlgError
        except np.linalg.LinAlgError:
            sol, *_ = np.linalg.lstsq(Gm, R, rcond=1e-12)
        return sol

    def _predict_general(self, p: Mapping[str, float], modal: Modal | None,
                         aff: AffinePieces | None = None) -> tuple[FloatArray, FloatArray]:
        """General path (non-uniform grid or defective ``A``): stepwise simulation.

        On a non-uniform grid with a diagonalisable ``A`` the modes are stepped interval by
        interval and the free response is the running product of the per-step
        ``exp(lam dt)`` (no simulation per initial-state direction).
        """
        m = self.model
        A, B = (modal.A, modal.B) if modal is not None else state_matrices(m, p, aff)
        Cm, Dm = self._output_maps(A, B)
        base_x0 = self._base_x0()
        X = simulate_states(m, p, self.t, self.U, base_x0, modal=modal, affine=aff)
        Y = X @ Cm.T + self.U @ Dm.T
        if isinstance(self.x0, str) and self.x0 == "estimate":
            if modal is not None:
                G = free_response_basis(modal, 0.0, self.t.size, Cm,
                                        modal_step_powers(modal, self.t))
            else:
                G = self._free_basis_slow(Cm, p, aff)
            sol = self._solve_x0(G, Y)
            Y = Y + G.reshape(-1, G.shape[2]).dot(sol).reshape(Y.shape)
            return Y, (free_coeffs_to_state(modal, sol) if modal is not None else sol)
        return Y, base_x0

    def _free_basis_slow(self, Cm: FloatArray, p: Mapping[str, float],
                         aff: AffinePieces | None = None) -> FloatArray:
        """Response of each channel to a unit initial state, shape (N, p, n) (general path)."""
        N = self.t.size
        n = self.model.n_states
        G = np.empty((N, len(self.channels), n))
        zeroU = np.zeros_like(self.U)
        for j in range(n):
            e = np.zeros(n)
            e[j] = 1.0
            G[:, :, j] = simulate_states(self.model, p, self.t, zeroU, e, affine=aff) @ Cm.T
        return G

    def residual_vector(self, p: Mapping[str, float]) -> FloatArray:
        """Weighted residuals of the observed samples, flattened (for Jacobians)."""
        r = self.predict(p).residual.reshape(-1) * self._w_flat
        return r if self._full else r[self._mask_flat]

    def residual_vectors(self, points: Sequence[Mapping[str, float]]) -> FloatArray:
        """Residual vectors of several parameter sets at once, shape (k, n_obs).

        Row ``i`` equals :meth:`residual_vector` of ``points[i]`` (to rounding, <= 1e-12
        relative; tested). On the fast path (uniform grid, no road input, every point's
        ``A`` diagonalisable with the same pattern of real modes and conjugate pairs, and
        with ``x0="estimate"`` no missing sample and a well-conditioned projection) the
        ``k`` evaluations share stacked numpy operations: one ``eig`` and one ``inv`` on
        the ``(k, n, n)`` stack, one running product for all ``k * m`` modes, batched
        products. Otherwise the points are evaluated one by one (the same errors raise).
        For finite-difference Jacobians, whose ``k`` points differ in one parameter each.

        Parameters
        ----------
        points : sequence of mapping
            Parameter sets (SI), each with every parameter of the model.

        Returns
        -------
        ndarray, shape (k, n_obs)
            Weighted residuals of the observed samples (units of the channels times their
            weights), each row flattened as :meth:`residual_vector`'s.
        """
        k = len(points)
        # a subclass with its own residuals (the monitor's window problem) is evaluated
        # point by point, through its own path
        own = (type(self).residual_vector is OutputErrorProblem.residual_vector
               and type(self).predict is OutputErrorProblem.predict)
        size = self.batch_size()
        R = np.empty((k, self.n_obs))
        for i in range(0, k, size):
            chunk = points[i:i + size]
            out = self._stacked_residuals(chunk) if len(chunk) > 1 and own else None
            if out is not None:
                R[i:i + len(chunk)] = out
            else:
                for j, q in enumerate(chunk):
                    R[i + j] = self.residual_vector(q)
        return R

    def batch_size(self) -> int:
        """Most points :meth:`residual_vectors` stacks at once.

        At most :data:`_STACK_POINTS`, and fewer when their powers (points x samples x
        modes) would exceed :data:`_STACK_ENTRIES`: a larger stack leaves the cache and is
        slower per point than one evaluation after another. With the initial state known
        (given or at rest) 1: stacking saved little there (no projection to share) and
        made the half car's Jacobian ~15 % slower (measured,
        ``python -m estimator.doe.evalbench``).
        """
        if not self._estimate:
            return 1
        per_point = self.t.size * max(self.model.n_states // 2, 1)
        return max(1, min(_STACK_POINTS, _STACK_ENTRIES // max(per_point, 1)))

    def _stacked_residuals(self, points: Sequence[Mapping[str, float]]) -> FloatArray | None:
        """The fast path of :meth:`residual_vectors`; ``None`` where it does not apply."""
        m = self.model
        if self.h is None or self._has_road or (self._estimate and not self._full):
            return None
        if not all(np.isfinite(v) for q in points for v in q.values()):
            return None
        k = len(points)
        if self._heights:
            # one set of ride-height rows for the stack: the points share the geometry
            geom = self._geometry(points[0])
            if any(self._geometry(q) != geom for q in points[1:]):
                return None
            self._set_heights(points[0])
        aff = self.pieces(points[0])
        mats = [state_matrices(m, q, aff) for q in points]
        A = np.stack([a for a, _ in mats])
        try:
            lam, V = np.linalg.eig(A)
            Vinv = np.linalg.inv(V)
        except np.linalg.LinAlgError:  # non-finite A, no convergence or a singular V
            return None
        # modal_form's test, point by point; one pattern of modes for the whole stack
        pattern = None
        for i in range(k):
            got = mode_pattern(lam[i], V[i], Vinv[i])
            if got is None:
                return None
            if lam.dtype.kind == "c" and int(got[1].sum()) == lam.shape[1]:
                return None  # modal_form would have worked in real arithmetic here
            if pattern is None:
                pattern = got
            elif not (np.array_equal(got[0], pattern[0]) and np.array_equal(got[1], pattern[1])):
                return None
        if pattern is None:
            return None
        keep, is_real = pattern
        lam = lam[:, keep]
        Vk = V[:, :, keep]
        if is_real.any():
            Vk[:, :, is_real] = Vk[:, :, is_real].real
        Vinv = Vinv[:, keep]
        fac = np.where(is_real, 1.0, 2.0)
        mm = keep.size
        if self._maps_fixed is not None:
            Cm = self._maps_fixed[0]
        else:
            Cm = np.stack([self._output_maps(a, b)[0] for a, b in mats])
        CV = (Cm @ Vk) * fac  # (k, p, mm)
        N = self.t.size
        E = np.exp(lam * float(self.h))  # (k, mm)
        P = _stack_powers(E, N)  # (k, N, mm)
        Y: np.ndarray | None = None
        if self._x0_nonzero:
            X = (CV * (Vinv @ self._x0_base)[:, None, :]).transpose(0, 2, 1)
            Y = _re_dot_stack(P, X)
        if self._estimate:
            sol = self._x0_closed_form_stack(fac, CV, E, P, Y)
            if sol is None:
                return None
            pairs = fac == 2.0
            c = sol[:, :mm].astype(complex)
            c[:, pairs] += 1j * sol[:, mm:]
            Yx = _re_dot_stack(P, (CV * c[:, None, :]).transpose(0, 2, 1))
            Y = Yx if Y is None else Y + Yx
        if Y is None:
            Y = np.zeros((k, N, len(self.channels)))
        r = (self.Ymeas.reshape(1, -1) - Y.reshape(k, -1)) * self._w_flat
        return r if self._full else r[:, self._mask_flat]

    def _x0_closed_form_stack(self, fac: FloatArray, CV: np.ndarray, E: np.ndarray,
                              P: np.ndarray, Y: FloatArray | None) -> FloatArray | None:
        """:meth:`_x0_closed_form` for ``k`` points at once (``CV`` (k, p, mm), ``E`` (k, mm),
        ``P`` (k, N, mm), ``Y`` (k, N, p) or ``None``); ``None`` if any point needs the
        explicit least squares."""
        mm = fac.size
        pairs = np.flatnonzero(fac == 2.0)
        modes = np.concatenate([np.arange(mm), pairs])
        alpha = np.concatenate([np.ones(mm), np.full(pairs.size, 1j)])
        Q = CV[:, :, modes] * alpha  # (k, p, n)
        w2 = self._w2
        Eg = E[:, modes]
        EN = P[:, -1][:, modes] * Eg
        N = P.shape[1]
        S1 = _geometric_sum(Eg[:, :, None] * Eg[:, None, :], EN[:, :, None] * EN[:, None, :], N)
        S2 = _geometric_sum(Eg[:, :, None] * np.conj(Eg)[:, None, :],
                            EN[:, :, None] * np.conj(EN)[:, None, :], N)
        Qw = Q.transpose(0, 2, 1) * w2
        GtG = 0.5 * np.real((Qw @ Q) * S1 + (Qw @ np.conj(Q)) * S2)
        R = self.Ymeas if Y is None else self.Ymeas - Y
        v = (_t_dot_stack(P, R) * (CV * w2[:, None]).transpose(0, 2, 1)).sum(axis=2)
        GtR = np.real(alpha * v[:, modes])
        try:
            sol = np.linalg.solve(GtG, GtR[..., None])[..., 0]
        except np.linalg.LinAlgError:  # a singular GtG
            return None
        if not np.isfinite(sol).all():
            return None
        if (np.linalg.cond(GtG) > 1e12).any():
            return None
        return np.asarray(sol, dtype=float)

    def normalized_ss(self, p: Mapping[str, float]) -> float:
        """Weighted sum of squares divided by the data's (dimensionless, 1 = no fit)."""
        try:
            if self._full:
                r = self.predict(p).residual
                if self._unit_w:
                    v = float(np.einsum("ij,ij->", r, r)) / self.scale
                else:
                    rw = r * self.w
                    v = float(np.einsum("ij,ij->", rw, rw)) / self.scale
            else:
                rv = self.residual_vector(p)
                v = float(rv @ rv) / self.scale
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            return np.inf
        return v if np.isfinite(v) else np.inf

    def seed_cost(self, ss: float) -> float:
        """Report the seed's cost from the raw weighted sum of squares ``ss``."""
        return float(np.sqrt(ss)) if self.cost == "frobenius" else float(ss)

    def rms_by_channel(self, res: FloatArray) -> dict[str, float]:
        """RMS residual per channel (SI)."""
        return {c: float(np.sqrt(np.nanmean(res[:, j] ** 2))) for j, c in enumerate(self.channels)}


def _geometric_sum(q: np.ndarray, qN: np.ndarray, N: int) -> np.ndarray:
    """``sum_{k<N} q**k`` elementwise, given ``qN = q**N`` (series near ``q = 1``)."""
    d = q - 1.0
    near = np.abs(d) < 1e-7
    safe = np.where(near, 1.0, d)
    out = (qN - 1.0) / safe
    if np.any(near):
        series = N + N * (N - 1) / 2.0 * d + N * (N - 1) * (N - 2) / 6.0 * d * d
        out = np.where(near, series, out)
    return out


def _re_dot(P: np.ndarray, X: np.ndarray) -> FloatArray:
    """``Re(P @ X)`` for a C-contiguous ``P`` (N, m) as one real product.

    A complex ``P`` is read as the real (N, 2 m) matrix of its interleaved real and
    imaginary parts, so ``Re(P @ X) = P_real_view @ [Re X; -Im X]`` (rows interleaved):
    one BLAS ``dgemm`` on contiguous memory, no copies of the real and imaginary parts.
    The one-point case of :func:`_re_dot_stack` (the same products, so batched and single
    evaluations agree bit for bit).
    """
    return _re_dot_stack(P[None], X[None])[0]


def _t_dot(P: np.ndarray, R: FloatArray) -> np.ndarray:
    """``P.T @ R`` for a C-contiguous ``P`` (N, m), real or complex, and real ``R`` (N, p).

    One real product over the samples on ``P``'s interleaved real view (see
    :func:`_re_dot`); returns (m, p), complex when ``P`` is. The one-point case of
    :func:`_t_dot_stack`.
    """
    return _t_dot_stack(P[None], R)[0]


def _stack_powers(E: np.ndarray, N: int) -> np.ndarray:
    """``E[i]**j`` for ``j = 0..N-1``: (k, N, m) from ``E`` (k, m), as :func:`powers` per row.

    Each point's block is C-contiguous like :func:`powers`' array, so the products on it
    run exactly as on a single point's (same running product, same BLAS calls).
    """
    k, m = E.shape
    P = np.empty((k, N, m), dtype=np.result_type(E, 1.0))
    if N == 0:
        return P
    P[:, 0] = 1.0
    if N > 1:
        np.multiply.accumulate(np.broadcast_to(E[:, None, :], (k, N - 1, m)), axis=1,
                               out=P[:, 1:])
    return P


def _re_dot_stack(P: np.ndarray, X: np.ndarray) -> FloatArray:
    """``Re(P[i] @ X[i])`` for every ``i``: ``P`` (k, N, m) C-contiguous, ``X`` (k, m, p).

    The stacked form of :func:`_re_dot` (one ``dgemm`` per point on the interleaved real
    view of its block); returns (k, N, p).
    """
    k, N, m = P.shape
    if P.dtype.kind != "c":
        return np.matmul(P, X.real)
    p = X.shape[2]
    Xs = np.empty((k, 2 * m, p))
    Xs[:, 0::2] = X.real
    Xs[:, 1::2] = -X.imag if X.dtype.kind == "c" else 0.0
    return np.matmul(P.view(np.float64), Xs)


def _t_dot_stack(P: np.ndarray, R: FloatArray) -> np.ndarray:
    """``P[i].T @ R[i]`` for every ``i`` (``R`` (N, p) shared or (k, N, p)): (k, m, p).

    The stacked form of :func:`_t_dot`.
    """
    if P.dtype.kind != "c":
        return np.matmul(P.transpose(0, 2, 1), R)
    M = np.matmul(P.view(np.float64).transpose(0, 2, 1), R)  # (k, 2 m, p)
    return M[:, 0::2] + 1j * M[:, 1::2]
