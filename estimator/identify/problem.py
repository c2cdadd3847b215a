"""The output-error identification problem for the linear models.

:class:`OutputErrorProblem` predicts the measured channels for a parameter vector and
returns the residual; the initial state follows by variable projection
(``x0="estimate"``), starts at equilibrium (``"rest"``) or is given. Costs: ``sse``, the
squared differences of the measured position channels, ride heights included (all
channels when no position is measured); ``frobenius``, the Frobenius norm over every
measured channel. Ride heights are strut extensions ``g . q + gr . r``
(:func:`ride_height_rows`).

The path is chosen per problem and parameter set: the fast path
(:meth:`OutputErrorProblem.evaluate`) on a uniform, fully observed grid with ``x0``
estimated; the modal recursion otherwise; stepwise simulation on a non-uniform grid or
for a defective ``A``. ``tests/core/test_cost_oracle.py`` checks each against
``scipy.integrate.solve_ivp``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np
from scipy.linalg.lapack import dgeev as _dgeev
from scipy.linalg.lapack import dsyev as _dsyev

from estimator.choices import COSTS
from suspid.errors import UsageError
from suspid.io.csvio import Measurement
from suspid.models.base import AffinePieces, FloatArray, SuspensionModel
from suspid.simulate import (MODE_COND_MAX, Modal, first_order_scan, foh_weights,
                             free_coeffs_to_state, free_response_basis, modal_form,
                             modal_step_powers, modal_trajectory, powers,
                             ride_height_maps, road_matrix, simulate_states, state_matrices,
                             uniform_step)

from estimator.identify.fastpath import (CACHE_BYTES, CACHE_SIZE, MAX_DECAY_EXPONENT, MAX_GRAM_COND,
                                         SS_GUARD, Evaluation, ForcedTrajectory, StateSpaceLayout,
                                         eigen_pattern, re_dot)
from estimator.identify.outputs import (Prediction, channel_kinds, check_magnitudes, output_maps,
                                        ride_height_rows)



@dataclass
class OutputErrorProblem:
    """Residuals of a linear suspension model against a measurement.

    Parameters
    ----------
    model : SuspensionModel
    meas : Measurement
    cost : {"sse", "frobenius"}
    x0 : "estimate", "rest" or ndarray
        Initial-state handling.
    weights : mapping, optional
        Per-channel weights multiplying the residual (default 1: the seed's raw SI cost).
    affine : AffinePieces, optional
        The model's affine pieces (:meth:`~suspid.models.base.SuspensionModel.affine`);
        default: built from the first prediction with every damper and spring free. A
        parameter set they do not apply to is predicted from the model itself.
    ride_heights : bool
        Whether measured ride heights enter the cost; ``False`` leaves them out with a warning.
    """

    model: SuspensionModel
    meas: Measurement
    cost: str = "sse"
    x0: str | FloatArray = "estimate"
    weights: Mapping[str, float] | None = None
    affine: AffinePieces | None = None
    ride_heights: bool = True
    channels: list[str] = field(init=False)
    warnings: list[str] = field(init=False, default_factory=list)

    def __post_init__(self) -> None:
        if self.cost not in COSTS:
            raise UsageError(f"unknown cost {self.cost!r}; expected one of {', '.join(COSTS)}")
        m = self.model
        motions = [c for c in m.channels if c in self.meas.measured]
        heights = [c for c in m.ride_height_channels if c in self.meas.measured]
        if heights and not self.ride_heights:
            self.warnings.append(f"ride-height channel(s) {', '.join(heights)} not compared "
                                 "(the monitor's window fits the motion channels only)")
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
        # weights and mask as flat (N p,) rows (a broadcast (p,) row is 3-4x slower)
        self._w_flat = np.tile(w, self.t.size)
        self._mask_flat = self.mask.reshape(-1)
        # ---- the fast path's constants (uniform grid, every sample observed, x0 estimated)
        nr = len(m.roads)
        N = int(self.t.size)
        self._nr = nr
        self._N = N
        #: evaluations by the fast path, cached per problem (see :meth:`evaluate`)
        self._cache: dict[tuple[float, ...], Evaluation] = {}
        #: the fast path applies to this problem (else every evaluation takes the general one)
        self.fast = bool(self.h is not None and self._full and self._estimate and N >= 2)
        #: evaluations the fast path declined and the general path made
        self.n_fallback = 0
        self.param_names = [q.name for q in m.params]
        self._layout: StateSpaceLayout | None = None
        self._hf = float(self.h) if self.h is not None else 0.0
        self.road_t = np.ascontiguousarray(self.U[:, :nr].T)  #: roads (nr, N) (m)
        self._rc = self.road_t.astype(complex)
        self._r0 = self.road_t[:, 0].copy() if N else np.zeros(nr)
        self._UT = np.ascontiguousarray(self.U.T)  # (2 nr, N)
        self._road = bool(np.any(self.road_t))
        self._YT = np.ascontiguousarray(self.Ymeas0.T)  # (p, N)
        # fitted channels that are states (positions, velocities): C V = V[rows]
        self.state_rows: list[int] | None = (
            [i + (self._nq if order == 1 else 0) for i, order in self._kind]
            if not self._heights and all(order < 2 for _, order in self._kind) else None)
        rows = self.state_rows or []
        self._rows_are_range = rows == list(range(len(rows)))
        self._pos_only = self.state_rows is not None and all(o == 0 for _, o in self._kind)
        self._cache_size = max(1, min(CACHE_SIZE, CACHE_BYTES // max(
            N * (16 * m.n_states + 8 * len(self.channels)), 1)))

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

    def state_space(self, vals: Sequence[float]
                    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """``(A, B, Bz, [B | Bz])`` for the values ``vals`` of every parameter (SI, in
        :attr:`param_names` order).

        ``Bz = A B_v + B_r`` is the road's input matrix in the simulator's ``z = x - B_v r``
        coordinates (:mod:`suspid.simulate`). From the affine pieces (:meth:`pieces`, laid
        out once as one product, see :class:`StateSpaceLayout`) when they apply to
        ``vals``, else from the model.
        """
        lay = self._layout
        if lay is None or lay.pieces is not self.affine:  # (new pieces: a new layout)
            lay = self._layout = None
            aff = self.pieces(dict(zip(self.param_names, vals)))
            if aff is not None and aff.exact and len(aff.names):
                lay = self._layout = StateSpaceLayout(aff, self.param_names, self._nr)
        if lay is not None and lay.applies(vals):
            return lay(vals)
        A, B = self.model.state_space(dict(zip(self.param_names, vals)))
        nr = self._nr
        Bz = A @ B[:, nr:] + B[:, :nr]
        return A, B, Bz, np.concatenate([B, Bz], axis=1)

    # ---- the fast path -------------------------------------------------------------------
    def cached(self, p: Mapping[str, float]) -> Evaluation | None:
        """The cached fast evaluation at ``p`` (``None``: not evaluated, or evicted)."""
        return self._cache.get(tuple([p[k] for k in self.param_names]))

    def evaluate(self, p: Mapping[str, float]) -> Evaluation | None:
        """One evaluation at ``p`` by the fast path, cached; ``None`` where it does not apply.

        It applies on a uniform grid with every fitted sample observed and ``x0="estimate"``
        (:attr:`fast`), at a diagonalisable ``A`` whose initial-state Gram matrix has a
        condition number below :data:`MAX_GRAM_COND`: the modal form from one LAPACK
        ``dgeev``, the forced first-order-hold trajectory in closed form (one ``cumsum`` per
        mode; the blocked scan when ``max(-Re(lam)) h N`` reaches
        :data:`MAX_DECAY_EXPONENT`), and the least-squares initial state from closed-form
        normal equations, the cost as ``||R0||^2 - rhs . sol`` unless the terms cancel
        (:data:`SS_GUARD`).
        """
        if not self.fast:
            return None
        names = self.param_names
        vals = [p[k] for k in names]
        key = tuple(vals)
        got = self._cache.get(key)
        if got is not None:
            return got
        if self._heights:
            self._set_heights(p)
        A, B, Bz, BB = self.state_space(vals)
        nr = self._nr
        wr, wi, vl, vr, info = _dgeev(A, compute_vl=1, compute_vr=1)
        if info != 0:
            return None
        wrl = wr.tolist()
        wil = wi.tolist()
        lim = 0.0
        for x, y in zip(wrl, wil):
            a = math.hypot(x, y)
            if not a < math.inf:  # NaN or inf
                return None
            if a > lim:
                lim = a
        tol = 1e-12 * (lim if lim > 1.0 else 1.0)
        for v in wil:
            if v != 0.0 and abs(v) <= tol:
                return None  # within rounding of the real axis: the general path decides
        pat = eigen_pattern(wil)
        if pat is None:
            return None
        n = len(wrl)
        # u_i^H v_i from the real parts: (a - ib)^T (c + id) = a.c + b.d + i (a.d - b.c)
        Mv = (vl.T @ vr).tolist()
        uv: list[complex] = []
        bound = 0.0
        for j, jj, pr in zip(pat.k1, pat.k2, pat.is_pair):
            x = (complex(Mv[j][j] + Mv[jj][jj], Mv[j][jj] - Mv[jj][j]) if pr
                 else complex(Mv[j][j], 0.0))
            if x == 0.0:
                return None
            uv.append(x)
            bound += (2.0 if pr else 1.0) / abs(x)
        # cond_1(V) <= sqrt(n) sum_i fac_i / |u_i^H v_i|: the exact test only above the limit
        if math.sqrt(n) * bound > MODE_COND_MAX:
            V = vr @ pat.sel_v
            Vinv = (vl @ pat.sel_v).conj().T / np.array(uv)[:, None]
            if (np.abs(V).sum(axis=0).max() * (np.abs(Vinv) * pat.fac[:, None]).sum(axis=0).max()
                    > MODE_COND_MAX):
                return None
        mm = len(uv)
        N = self._N
        h = self._hf
        lam = [complex(wrl[j], wil[j]) for j in pat.k1]
        # fitted channels per mode: CV = (Cm V) fac
        rows = self.state_rows
        if rows is not None:
            CV = (vr[:len(rows)] if self._rows_are_range else vr[rows]) @ pat.sel_cv
            Cm = Dm = None
        else:
            Cm, Dm = self._output_maps(A, B)
            CV = (Cm @ vr) @ pat.sel_cv
        # per mode, E = exp(lam h), b = V^-1 Bz, w0 = -V^-1 Bv r[0]:
        #   w[k] = (a0 + a1) E^k Q[k] - a0 r[k] + (w0 - a1 r[0]) E^k,
        # Q = cumsum(r[l] E^-l), a0 = b g0 / E, a1 = b g1; the last term is a free response,
        # absorbed by the least-squares initial state (taken out again in Evaluation.c)
        lam_a = np.array(lam)
        El_a, g0a, g1a = foh_weights(lam_a, h)  # (m,) each
        P = np.empty((mm, N), dtype=complex)
        P[:] = El_a[:, None]
        P[:, 0] = 1.0
        np.cumprod(P, axis=1, out=P)
        r = self.road_t
        if self._road:
            # rows of V^-1 [Br | Bv | Bz] from the left eigenvectors: (a - ib)^T B / (u_i^H v_i)
            VZ = vl.T @ BB
            X = (VZ[pat.k1a] - 1j * (VZ[pat.k2a] * pat.pair_mask[:, None])) / np.array(uv)[:, None]
            Xb = X[:, 2 * nr:]  # b = V^-1 Bz
            if max(-x.real for x in lam) * h * (N - 1) <= MAX_DECAY_EXPONENT:
                Cb = Xb * (g0a / El_a)[:, None]  # a0
                a1 = Xb * g1a[:, None]
                cc = -((X[:, nr:2 * nr] + a1) @ self._r0)  # w0 - a1 r[0], w0 = -V^-1 Bv r[0]
                # the roads summed first: Wf[k] = E^k cumsum_l((sum_j Ca_j r_j[l]) E^-l)
                Wf = (Cb + a1) @ self._rc
                np.divide(Wf, P, out=Wf)
                np.cumsum(Wf, axis=1, out=Wf)
                Wf *= P
                # R = Y - Re(CV Wf - (CV Cb) r)
                R = self._YT - (CV @ Wf).real
                R += (CV @ Cb).real @ r
            else:
                # E^-N would overflow: the forced trajectory from rest by the blocked scan
                S = Xb @ r
                w0 = -(X[:, nr:2 * nr] @ self._r0)
                Wf = np.empty((mm, N), dtype=complex)
                Wf[:, 0] = w0
                Wf[:, 1:] = first_order_scan(
                    El_a, (g0a[:, None] * S[:, :-1] + g1a[:, None] * S[:, 1:]).T, w0).T
                Cb = np.zeros((mm, nr), dtype=complex)
                cc = np.zeros(mm, dtype=complex)
                R = self._YT - (CV @ Wf).real
            if not self._pos_only:  # x = z + B_v r
                CB = B[rows, nr:] if Cm is None else Cm @ B[:, nr:]
                R -= CB @ r
            traj: ForcedTrajectory | None = ForcedTrajectory(Wf, Cb, cc)
        else:
            R = self._YT.copy()
            traj = None
        if Dm is not None and self._has_road:
            R -= Dm @ self._UT
        # least-squares free modal coefficients, regressors Re(CV_i E_i^k) and -Im(...): with
        # x = CV_ci E_i^k, y = CV_cj E_j^k, S1 = sum x y = (CV^T CV)_ij g(E_i E_j) and
        # S2 = sum x conj(y), g(z) = (1 - z^N) / (1 - z), the Gram matrix is
        # Re x Re y = Re(S1 + S2) / 2, Im x Im y = Re(S2 - S1) / 2, Re x Im y = Im(S1 - S2) / 2
        if self._unit_w:
            CVw, Rw = CV, R
        else:
            CVw, Rw = CV * self.w[:, None], R * self.w[:, None]
        sAB = np.empty((2, mm, mm), dtype=complex)  # (lam_i + lam_j) h, (lam_i + lam_j*) h
        np.add(lam_a[:, None], lam_a[None, :], out=sAB[0])
        np.add(lam_a[:, None], lam_a.conj()[None, :], out=sAB[1])
        sAB *= h
        gAB = np.expm1(N * sAB)
        gAB /= np.expm1(sAB)
        CC = CVw.T @ np.concatenate([CVw, CVw.conj()], axis=1)  # [CV^T CV | CV^T conj(CV)]
        S1 = CC[:, :mm] * gAB[0]
        S2 = CC[:, mm:] * gAB[1]
        pairs = pat.pairs
        npair = pairs.size
        nG = mm + npair
        Gram = np.empty((nG, nG))
        Gram[:mm, :mm] = 0.5 * (S1 + S2).real
        if npair:
            D = 0.5 * (S2 - S1)
            Gram[mm:, mm:] = D.real[pat.ix_pairs]
            Gram[:mm, mm:] = D.imag[:, pairs]  # Re x_i (-Im y_j) = Im(S2 - S1)_ij / 2
            Gram[mm:, :mm] = Gram[:mm, mm:].T
        ev, vec, info = _dsyev(Gram)
        evl = ev.tolist()
        if info != 0 or not (evl[0] > 0 and evl[-1] <= MAX_GRAM_COND * evl[0]):
            return None
        # regressors times the residual: Re(y_i), -Im(y_i) with
        # y_i = sum_k E_i^k (CV^T R)_ik = sum_c CV_ci (R P^T)_ci
        y = (CVw * (Rw @ P.T)).sum(axis=0)
        rhs = np.concatenate([y.real, -y.imag[pairs]])
        proj = rhs @ vec
        sol = vec @ (proj / ev)  # not finite only if R is: the cost is then inf
        coef = sol[:mm].astype(complex)
        if npair:
            coef[pairs] += 1j * sol[mm:]
        # the cost without a residual pass, ||R0||^2 - rhs . sol (explicit where they cancel)
        r0 = Rw.ravel()
        r0sq = float(r0 @ r0)
        ss = r0sq - float(proj @ (proj / ev))
        out = Evaluation(key, vr, pat, A, B, P, traj, coef, R, CV, ss)
        if not ss >= SS_GUARD * r0sq:
            rf = out.R if self._unit_w else out.R * self.w[:, None]
            out.ss = float(np.einsum("ij,ij->", rf, rf))
        cache = self._cache
        if len(cache) >= self._cache_size:
            del cache[next(iter(cache))]  # oldest first
        cache[key] = out
        return out

    def initial_state(self, ev: Evaluation) -> FloatArray:
        """The estimated initial state of an evaluation (n,) (SI)."""
        return np.real((ev.vr @ ev.pat.sel_v) @ (ev.c * ev.pat.fac))

    def _fast_or_none(self, p: Mapping[str, float]) -> Evaluation | None:
        """:meth:`evaluate` where the fast path applies, counting what it declines."""
        if not self.fast:
            return None
        ev = self.evaluate(p)
        if ev is None:
            self.n_fallback += 1
        return ev

    # ---- predictions and costs -------------------------------------------------------------
    def predict(self, p: Mapping[str, float]) -> Prediction:
        """Predict the measured channels for parameters ``p`` (with the best ``x0``).

        The fast path (:meth:`evaluate`) where it applies; otherwise the modal recursion
        (uniform grid, diagonalisable ``A``: missing samples, a known ``x0``) or the
        stepwise simulation (a non-uniform grid, a defective ``A``).
        """
        ev = self._fast_or_none(p)
        if ev is not None:
            res = ev.R.T.copy()
            return Prediction(Y=self.Ymeas - res, x0=self.initial_state(ev), residual=res)
        self._set_heights(p)
        aff = self.pieces(p)
        modal = modal_form(self.model, p, aff)
        if modal is not None and self.h is not None:
            Y, x0 = self._predict_modal(modal, self.h)
        else:
            Y, x0 = self._predict_general(p, modal, aff)
        if self._full:
            res = self.Ymeas - Y
        else:
            res = np.where(self.mask, self.Ymeas - Y, np.nan)
        return Prediction(Y=Y, x0=x0, residual=res)

    def _predict_modal(self, modal: Modal, h: float) -> tuple[FloatArray, FloatArray]:
        """Modal recursion on a uniform grid (diagonalisable ``A``) where the fast path
        does not apply: a known ``x0`` (closed form), missing samples (the initial state by
        explicit weighted least squares on the observed samples)."""
        m = self.model
        N = self.t.size
        h = float(h)
        Cm, Dm = self._output_maps(modal.A, modal.B)
        CV = (Cm @ modal.V) * modal.fac  # (p, mm)
        base_x0 = self._x0_base
        E = np.exp(modal.lam * h)
        P: np.ndarray | None = None  # powers of E, built once and only where needed
        Y: FloatArray | None = None  # None: the zero response (no road, x0 at rest)
        if self._has_road:
            nr = len(m.roads)
            r = self.U[:, :nr]
            W = modal_trajectory(modal, h, r, base_x0)
            Y = re_dot(W, CV.T) + r @ (Cm @ modal.Bv).T + self.U @ Dm.T
        elif self._x0_nonzero:
            P = powers(E, N)
            Y = re_dot(P, (CV * (modal.Vinv @ base_x0)).T)
        if Y is None:
            Y = np.zeros((N, len(self.channels)))
        if not self._estimate:
            return Y, base_x0
        G = free_response_basis(modal, h, N, Cm, P if P is not None else powers(E, N))
        sol = self._solve_x0(G, Y)
        Y = Y + G.reshape(-1, G.shape[2]).dot(sol).reshape(Y.shape)
        return Y, free_coeffs_to_state(modal, sol)

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
        base_x0 = self._x0_base
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
        ev = self._fast_or_none(p)
        if ev is not None:
            return (ev.R.T.ravel() if self._unit_w
                    else (ev.R * self.w[:, None]).T.ravel())
        r = self.predict(p).residual.reshape(-1) * self._w_flat
        return r if self._full else r[self._mask_flat]

    def residual_vectors(self, points: Sequence[Mapping[str, float]]) -> FloatArray:
        """Residual vectors of several parameter sets, shape (k, n_obs).

        Row ``i`` is :meth:`residual_vector` of ``points[i]`` (the same path and errors).

        Parameters
        ----------
        points : sequence of mapping
            Parameter sets (SI), each with every parameter of the model.

        Returns
        -------
        ndarray, shape (k, n_obs)
            Weighted residuals of the observed samples.
        """
        R = np.empty((len(points), self.n_obs))
        for i, q in enumerate(points):
            R[i] = self.residual_vector(q)
        return R

    def normalized_ss(self, p: Mapping[str, float]) -> float:
        """Weighted sum of squares divided by the data's (dimensionless, 1 = no fit)."""
        try:
            ev = self._fast_or_none(p)
            if ev is not None:
                v = ev.ss / self.scale
            elif self._full:
                r = self.predict(p).residual
                if self._unit_w:
                    v = float(np.einsum("ij,ij->", r, r)) / self.scale
                else:
                    rw = r * self.w
                    v = float(np.einsum("ij,ij->", rw, rw)) / self.scale
            else:
                rv = self.residual_vector(p)
                v = float(rv @ rv) / self.scale
        except (np.linalg.LinAlgError, ValueError, FloatingPointError, OverflowError,
                ZeroDivisionError):
            return np.inf
        return v if np.isfinite(v) else np.inf

    def seed_cost(self, ss: float) -> float:
        """Report the seed's cost from the raw weighted sum of squares ``ss``."""
        return float(np.sqrt(ss)) if self.cost == "frobenius" else float(ss)
