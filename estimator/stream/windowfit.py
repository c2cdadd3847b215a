"""A monitor window's fit beyond its cost: stderr, Gauss-Newton steps, drifting parameters.

A window's cost, residuals and initial state are those of the one output-error problem,
:class:`~estimator.identify.OutputErrorProblem`, on its fast path
(:meth:`~estimator.identify.OutputErrorProblem.evaluate`: a uniform grid with every sample
observed and the initial state estimated, evaluations cached per problem). A warm window is
fitted with ~10 Nelder-Mead evaluations on ~750 samples; :class:`WindowFit` reuses those
cached evaluations:

* :meth:`WindowFit.finish` -- the result at the optimum with stderr from the secant through
  Nelder-Mead's final simplex (no further evaluation);
* :meth:`WindowFit.gauss_newton` -- chord Gauss-Newton steps from Nelder-Mead's best vertex;
* :meth:`WindowFit.drift_residual` -- the window with some parameters drifting linearly in
  time (``WindowConfig.drift``): ``A`` and ``Bz`` per chunk of the window, one batched
  matrix exponential for every chunk's first-order-hold discretisation, the initial state
  again by least squares; with zero rates it equals the constant window's residual to
  rounding. :meth:`WindowFit.drift_sensitivity` is its first-order form around the constant
  fit.

Where the fast path does not apply (a gap in the window, a non-uniform grid) the core's
:func:`estimator.identify.finish` is used.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np
from scipy.linalg import expm as _expm
from scipy.linalg.lapack import dgeqrf as _dgeqrf
from scipy.linalg.lapack import dgesv as _dgesv
from scipy.linalg.lapack import dsyev as _dsyev

from estimator.identify import OutputErrorProblem, Parameters, finish
from estimator.identify.identifiability import WEAK_TOL, Identifiability, assess
from estimator.identify.fastpath import Evaluation
from estimator.identify.outputs import channel_kinds, output_maps
from estimator.identify.result import IdentResult
from suspid.models.base import FloatArray
from suspid.simulate import foh_weights

#: largest final-simplex edge (log units) and edge-matrix condition number (1-norm) for
#: which the Jacobian is taken from the simplex's residuals (secant) instead of forward
#: differences
SECANT_MAX_EDGE = 0.02
SECANT_MAX_COND = 1e3
#: farthest (log units, per parameter) the Gauss-Newton steps go from Nelder-Mead's best
#: vertex: a loose Nelder-Mead in twelve dimensions stops up to 4 % from the window's
#: optimum (measured on the full car's maintenance stream)
GAUSS_NEWTON_MAX_STEP = 0.06

_UPPER: dict[int, FloatArray] = {}


def small_inverse(M: FloatArray) -> tuple[FloatArray | None, float]:
    """Inverse of a small square matrix and its 1-norm condition number.

    Closed form for 1x1 and 2x2, one LAPACK ``dgesv`` (LU with partial pivoting) on the
    identity otherwise; ``(None, inf)`` when ``M`` is singular or not finite.
    ``cond_1 = ||M||_1 ||M^-1||_1``.
    """
    n = M.shape[0]
    if n <= 2:
        if n == 1:
            a = float(M[0, 0])
            if a == 0.0 or not math.isfinite(a):
                return None, math.inf
            return np.array([[1.0 / a]]), 1.0
        (a, b), (c, d) = M.tolist()
        det = a * d - b * c
        if det == 0.0 or not math.isfinite(det):
            return None, math.inf
        inv = [[d / det, -b / det], [-c / det, a / det]]
        n1 = max(abs(a) + abs(c), abs(b) + abs(d))
        n2 = max(abs(inv[0][0]) + abs(inv[1][0]), abs(inv[0][1]) + abs(inv[1][1]))
        return np.array(inv), n1 * n2
    if not np.isfinite(M).all():
        return None, math.inf
    _, _, Minv, info = _dgesv(M, np.eye(n))
    if info != 0 or not np.isfinite(Minv).all():
        return None, math.inf
    return Minv, float(np.abs(M).sum(axis=0).max() * np.abs(Minv).sum(axis=0).max())


def _verdict(small: FloatArray, free: list[str], kinds: dict[str, str],
             structural: tuple[str, ...] = ()) -> Identifiability:
    """:func:`~estimator.identify.identifiability.assess` of a square QR factor.

    When every relative singular value is at least the weak-identifiability threshold the
    verdict is "identifiable, no warning" and only the singular values are needed: closed
    form for 2x2; otherwise (or for larger factors) ``assess`` itself.
    """
    if small.shape == (2, 2) and not (structural and set(structural) <= set(free)):
        (a, b), (c, d) = small.tolist()
        ssq = a * a + b * b + c * c + d * d
        det = abs(a * d - b * c)
        if math.isfinite(ssq) and ssq > 0.0:
            s1 = math.sqrt(0.5 * (ssq + math.sqrt(max(ssq * ssq - 4.0 * det * det, 0.0))))
            s2 = det / s1
            if s2 / s1 >= WEAK_TOL:
                return Identifiability(True, [1.0, s2 / s1])
    return assess(small, free, kinds, structural)


@dataclass
class GaussNewton:
    """Outcome of :meth:`WindowFit.gauss_newton`."""

    params: dict[str, float] | None  # the parameters reached (SI); None: no step taken
    jacobian: FloatArray | None  # residual Jacobian (log-parameters) at the start
    nfev: int  # evaluations used


class WindowFit:
    """What a monitor window needs beyond its cost, on the one output-error problem.

    The cost, residuals and initial state are :class:`~estimator.identify.OutputErrorProblem`'s
    (its fast path, :meth:`~estimator.identify.OutputErrorProblem.evaluate`, cached per
    problem); this layer adds the window's result at the optimum (:meth:`finish`: stderr
    from the final simplex's secant), Gauss-Newton steps from Nelder-Mead's best vertex
    (:meth:`gauss_newton`) and the window with drifting parameters (:meth:`drift_residual`,
    :meth:`drift_sensitivity`, :meth:`drift_stderr`).

    Parameters
    ----------
    problem : OutputErrorProblem
        The window's problem (built with ``ride_heights=False``: the window compares the
        motion channels).
    """

    def __init__(self, problem: OutputErrorProblem) -> None:
        self.problem = problem
        m = problem.model
        self.model = m
        #: ``(free, p_hat, J)`` of the last fast :meth:`finish`: ``J`` (p N x n_free) the
        #: derivative of the predicted fitted channels (channel-major rows) with respect to
        #: the log-parameters at ``p_hat``
        self.jacobian: tuple[list[str], dict[str, float], FloatArray] | None = None
        self._nq = len(m.coords)
        self._nr = len(m.roads)
        self._N = int(problem.t.size)
        self._names = problem.param_names
        self._r = problem.road_t
        self._hf = float(problem.h) if problem.h is not None else 0.0
        self._rows = problem.state_rows or []
        self._pos_only = all(i < self._nq for i in self._rows)
        # every measured model channel (for the RMS of all channels at the optimum)
        self._all = [c for c in m.channels if c in problem.meas.measured]
        self._all_kind = channel_kinds(m.coords, self._all)

    def _all_outputs(self, ev: Evaluation) -> FloatArray:
        """Every measured model channel (rows) of an evaluation, from its estimated ``x0``."""
        Cm, Dm = output_maps(self._all_kind, ev.A, ev.B, self._nq)
        CV = (Cm @ ev.vr) @ ev.pat.sel_cv
        Y = (CV @ ev.modal(self._r)).real + (Cm @ ev.B[:, self._nr:]) @ self._r + Dm @ self.problem.U.T
        return Y

    # ---- result at the optimum ----------------------------------------------------------------
    def finish(self, params: Parameters, p_hat: Mapping[str, float], nfev: int,
               converged: bool, simplex: list[Mapping[str, float]] | None = None,
               rel_step: float = 1e-6, jacobian: FloatArray | None = None) -> IdentResult:
        """:func:`estimator.identify.finish` for a window: result, stderr, identifiability.

        Same quantities and formulas (RMS of every measured channel, per-channel residual
        variance, sandwich covariance of the log-parameters, identifiability verdict on the
        noise-normalised Jacobian), with the evaluations reused on the fast path:

        * the residual at ``p_hat`` is Nelder-Mead's best vertex (cached);
        * the Jacobian of the residuals with respect to the log-parameters is the *secant*
          through Nelder-Mead's final simplex (``simplex``: its vertices, best first, all
          evaluated already): ``J = dR D^-1`` with ``D`` the edges from the best vertex
          (log units) and ``dR`` the residual differences. With edges of ~``xatol``
          (0.2 %) its truncation error is ~0.1-1 % of the Jacobian, i.e. of ``stderr_fit``
          (itself a small part of ``stderr`` next to the ``sigma_floor``). When an edge
          is longer than :data:`SECANT_MAX_EDGE`, the edge matrix is ill-conditioned
          (condition number > :data:`SECANT_MAX_COND`) or a vertex was not evaluated on
          the fast path, ``jacobian`` when given (the Gauss-Newton steps' forward
          difference, within :data:`GAUSS_NEWTON_MAX_STEP` of ``p_hat``), else a forward
          difference (``rel_step``, ``n_free`` evaluations) is used instead.

        Off the fast path: :func:`estimator.identify.finish` (central differences).

        Parameters
        ----------
        params : Parameters
            Free/fixed split (the values are not used).
        p_hat : mapping
            The estimate, every parameter (SI).
        nfev : int
            Nelder-Mead evaluations (reported).
        converged : bool
        simplex : list of mapping, optional
            Nelder-Mead's final simplex as parameter sets (SI), best vertex first.
        rel_step : float
            Forward-difference step in log-parameter units.
        jacobian : ndarray, optional
            Residual Jacobian (log-parameters, channel-major rows, as
            :meth:`gauss_newton` returns it) near ``p_hat``, used when the secant is not.

        Returns
        -------
        IdentResult
        """
        free = params.free
        ev = self.problem.evaluate(p_hat)
        if ev is None or not free:
            return finish(self.problem, params, p_hat, nfev, converged, with_stderr=True)
        model = self.model
        pch, N = ev.R.shape
        r0 = ev.R.ravel()
        x0 = self.problem.initial_state(ev)
        Yall = self._all_outputs(ev)
        Mall = np.array([np.asarray(self.problem.meas.measured[c], dtype=float) for c in self._all])
        rms = dict(zip(self._all, np.sqrt(((Mall - Yall) ** 2).mean(axis=1)).tolist()))
        nf = len(free)
        J = self._secant(free, p_hat, r0, simplex)
        if J is None and jacobian is not None and jacobian.shape == (r0.size, nf):
            J = jacobian
        if J is None:
            J = self._forward_jacobian(free, p_hat, r0, rel_step)
            if J is None:
                return finish(self.problem, params, p_hat, nfev, converged, with_stderr=True)
        # residual = y - yhat, so -d(residual) = d(yhat); rows channel-major (j*N + k)
        J = -J
        self.jacobian = (list(free), dict(p_hat), J)
        n_obs = pch * N
        ss = float(r0 @ r0)
        dof = max(n_obs - nf, 1) / n_obs
        sig2 = (ev.R * ev.R).sum(axis=1) / (N * dof)
        warnings = list(self.problem.meas.warnings) + list(self.problem.warnings)
        scale_c = np.sqrt(np.where(sig2 > 0, sig2, 0.0))
        ref = np.sqrt((self.problem.Ymeas0 * self.problem.Ymeas0).mean(axis=0))
        scale_c = np.where(scale_c > 1e-9 * np.maximum(ref, 1e-300), scale_c,
                           np.maximum(ref, 1e-300))
        J3 = J.reshape(pch, N, nf)
        Jn = (J3 / scale_c[:, None, None]).reshape(n_obs, nf)
        # the verdict needs the singular values and right singular vectors of Jn only:
        # those of its QR factor R (n_free x n_free), computed without an SVD of Jn
        qr, _, _, info = _dgeqrf(Jn)
        small = qr[:nf] * self._upper(nf)
        if info != 0 or not np.isfinite(small).all():
            small = Jn
        verdict = _verdict(small, free, {q.name: q.kind for q in model.params},
                           model.scale_invariant)
        identifiable = verdict.identifiable
        warnings += verdict.warnings
        stderr: dict[str, float] = {k: float("nan") for k in free}
        cov_log = None
        H = J.T @ J
        # pseudo-inverse of the symmetric H (as numpy's pinv with rcond=1e-12)
        w, Q, info = _dsyev(H)
        wl = w.tolist()
        cut = 1e-12 * max(abs(x) for x in wl) if wl else 0.0
        if info == 0 and all(math.isfinite(x) for x in wl) and cut > 0:
            Hinv = (Q * np.array([1.0 / x if abs(x) > cut else 0.0 for x in wl])) @ Q.T
            Bm = (J3 * sig2[:, None, None]).reshape(n_obs, nf).T @ J
            cov_log = Hinv @ Bm @ Hinv
            for i, k in enumerate(free):
                d = math.sqrt(max(float(cov_log[i, i]), 0.0))
                stderr[k] = float(p_hat[k] * d) if identifiable else float("inf")
        else:
            warnings.append("could not invert the sensitivity matrix for standard errors")
        nss = ss / self.problem.scale
        aic = n_obs * math.log(max(nss, 1e-300) / n_obs) + 2 * nf
        bic = n_obs * math.log(max(nss, 1e-300) / n_obs) + nf * math.log(n_obs)
        if not converged:
            warnings.append("Nelder–Mead stopped on its evaluation budget before converging")
        return IdentResult(
            model=model.name, params={k: float(v) for k, v in p_hat.items()},
            fixed=params.fixed, stderr=stderr, cost=self.problem.seed_cost(ss), nfev=nfev,
            success=bool(converged and identifiable), rms_residual=rms,
            identifiable=identifiable, warnings=warnings, x0=[float(v) for v in x0],
            aic=aic, bic=bic, n_obs=n_obs, singular_values=verdict.singular_values,
            cov_log=cov_log)

    def gauss_newton(self, free: list[str], p_hat: Mapping[str, float], steps: int = 1,
                     rel_step: float = 1e-6) -> GaussNewton:
        """Gauss-Newton steps from Nelder-Mead's best vertex on one Jacobian.

        Nelder-Mead stops with every vertex within ``xatol`` of the best one, not at the
        optimum; from there a Gauss-Newton step on the residuals' Jacobian (forward
        differences of ``rel_step`` in log units at ``p_hat``: ``n_free`` evaluations)
        lands much closer to it. Each step ``du = -J^+ R(p)`` (one evaluation; shortened
        to end within :data:`GAUSS_NEWTON_MAX_STEP` of ``p_hat`` in every parameter, a
        trust region) is taken while it lowers the cost; up to ``steps`` of them, all on
        the Jacobian at ``p_hat`` (the chord method: near the optimum the Jacobian barely
        changes, and a new one would cost ``n_free`` evaluations per step).

        Parameters
        ----------
        free : list of str
            Free parameter names.
        p_hat : mapping
            Nelder-Mead's best vertex, every parameter (SI).
        steps : int
            Most steps taken.
        rel_step : float
            Forward-difference step (log units).

        Returns
        -------
        GaussNewton
            The parameters reached (``None``: not on the fast path or no step lowered the
            cost), the Jacobian at ``p_hat`` (``None`` off the fast path) and the
            evaluations used.
        """
        ev = self.problem.evaluate(p_hat)
        if ev is None or not free:
            return GaussNewton(None, None, 0)
        r = ev.R.ravel()
        J = self._forward_jacobian(free, p_hat, r, rel_step)
        nfev = len(free)
        if J is None:
            return GaussNewton(None, None, nfev)
        # the normal equations (n_free x n_free, formed once): a QR factorisation of the
        # tall J with its explicit Q costs as much as three evaluations; each step is
        # checked on the cost anyway
        H = J.T @ J
        u = np.zeros(len(free))
        ss = ev.ss
        best: dict[str, float] | None = None
        for _ in range(steps):
            try:
                un = u + np.linalg.solve(H, -(J.T @ r))
            except np.linalg.LinAlgError:
                break
            if not np.all(np.isfinite(un)):
                break
            far = float(np.abs(un).max())
            if far > GAUSS_NEWTON_MAX_STEP:  # back along the step to the trust region's edge
                un = u + (un - u) * ((GAUSS_NEWTON_MAX_STEP - float(np.abs(u).max()))
                                     / (far - float(np.abs(u).max())))
            q = dict(p_hat)
            for k, d in zip(free, un.tolist()):
                q[k] = p_hat[k] * math.exp(d)
            nfev += 1
            try:
                eq = self.problem.evaluate(q)
            except (np.linalg.LinAlgError, ValueError, FloatingPointError, OverflowError,
                    ZeroDivisionError):
                eq = None
            if eq is None or not eq.ss < ss:
                break
            u, ss, best, r = un, eq.ss, q, eq.R.ravel()
        return GaussNewton(best, J, nfev)

    def _forward_jacobian(self, free: list[str], p_hat: Mapping[str, float], r0: FloatArray,
                          rel_step: float) -> FloatArray | None:
        """Residual Jacobian (log-parameters) by forward differences on the fast path.

        ``r0`` is the residual at ``p_hat`` (channel-major); one evaluation per free
        parameter, step ``rel_step`` (log units). ``None`` when an evaluation leaves the
        fast path.
        """
        cols = []
        for k in free:
            q = dict(p_hat)
            q[k] = p_hat[k] * math.exp(rel_step)
            ek = self.problem.evaluate(q)
            if ek is None:
                return None
            cols.append((ek.R.ravel() - r0) / rel_step)
        return np.column_stack(cols)

    def _secant(self, free: list[str], p_hat: Mapping[str, float], r0: FloatArray,
                simplex: list[Mapping[str, float]] | None) -> FloatArray | None:
        """Residual Jacobian (log-parameters) from the final simplex, or ``None``."""
        nf = len(free)
        if simplex is None or len(simplex) != nf + 1:
            return None
        l0 = [math.log(p_hat[k]) for k in free]
        D = np.empty((nf, nf))
        dR = np.empty((r0.size, nf))
        for i, q in enumerate(simplex[1:]):
            ek = self.problem.cached(q)
            if ek is None:
                return None
            D[i] = [math.log(q[k]) - a for k, a in zip(free, l0)]
            dR[:, i] = ek.R.ravel() - r0
        if not np.abs(D).max() <= SECANT_MAX_EDGE:
            return None
        Dinv, cond = small_inverse(D)
        if Dinv is None or cond > SECANT_MAX_COND:
            return None
        # dR = J D^T  ->  J = dR D^-T
        return dR @ Dinv.T

    # ---- linear drift inside the window --------------------------------------------------
    @property
    def drift_ok(self) -> bool:
        """Whether :meth:`drift_residual` applies (fast path, fitted channels are states)."""
        return bool(self.problem.fast and self.problem.state_rows)

    def drift_residual(self, p: Mapping[str, float], rates: Mapping[str, float],
                       t_ref: float, chunk_s: float) -> FloatArray | None:
        """Residual (p, N) of a window whose parameters drift linearly in time.

        ``theta_k(t) = p_k (1 + g_k (t - t_ref))`` for every ``k`` in ``rates`` (``g_k``
        relative rate, 1/s), the others constant at ``p``. The window is cut into chunks of
        ``chunk_s``; in each ``A`` and ``Bz`` are taken at the chunk's middle time and the
        first-order-hold road is discretised exactly (one matrix exponential per chunk).
        The initial state is fitted by least squares as on the constant path; with every
        rate zero the residual equals the fast evaluation's to rounding. ``None`` when
        :attr:`drift_ok` is false, a chunk's matrices are not finite or a drifting parameter
        enters ``B_v`` (the road-rate input).
        """
        if not self.drift_ok:
            return None
        h = self._hf
        N = self._N
        n = self.model.n_states
        nr = self._nr
        K = max(1, int(round(chunk_s / h)))
        vals = [float(p[k]) for k in self._names]
        idx = [(self._names.index(k), float(p[k]), float(g)) for k, g in rates.items()]
        t = self.problem.t
        rows = self._rows
        # chunks c = 0..C-1 of K steps each (the last one padded), all discretised at once
        C = -(-(N - 1) // K)
        tc = np.minimum(np.arange(C + 1) * K, N - 1)
        tm = 0.5 * (t[tc[:-1]] + t[tc[1:]]) - t_ref
        nb = n + 2 * nr
        aug = np.zeros((C, nb, nb))
        aug[:, n:n + nr, n + nr:] = np.eye(nr)
        Bv = None
        for c in range(C):
            v = list(vals)
            for i, base, g in idx:
                v[i] = base * (1.0 + g * float(tm[c]))
                if v[i] <= 0.0:
                    return None
            A, B, Bz, _ = self.problem.state_space(v)
            if Bv is None:
                Bv = B[:, nr:].copy()
            elif c == C - 1 and float(np.abs(B[:, nr:] - Bv).max()) > 1e-12 * float(
                    np.abs(Bv).max()):
                # B_v is affine in the parameters, which move linearly in time: equal at
                # the first and last chunk means constant. Otherwise a drifting tyre
                # damping: z = x - B_v r would change in time
                return None
            aug[c, :n, :n] = A * h
            aug[c, :n, n:n + nr] = Bz * h
        F = _expm(aug)
        if not np.isfinite(F).all():
            return None
        Phi = F[:, :n, :n]
        rp = np.empty((nr, C * K + 1))
        rp[:, :N] = self._r
        rp[:, N:] = self._r[:, -1:]
        r0 = rp[:, :-1].reshape(nr, C, K)
        dr = np.diff(rp, axis=1).reshape(nr, C, K)
        # forcing of step i of chunk c: G1 r[k] + G2 (r[k+1] - r[k])  -> (C, K, n)
        f = (np.einsum("cnj,jci->cin", F[:, :n, n:n + nr], r0)
             + np.einsum("cnj,jci->cin", F[:, :n, n + nr:], dr))
        # within each chunk (all chunks at once): powers Phi^i and the forced part from rest
        Pw = np.empty((C, K + 1, n, n))
        Z = np.empty((C, K + 1, n))
        Pw[:, 0] = np.eye(n)
        Z[:, 0] = 0.0
        for i in range(K):
            Pw[:, i + 1] = Phi @ Pw[:, i]
            Z[:, i + 1] = (Phi @ Z[:, i, :, None])[:, :, 0] + f[:, i]
        # chunk starts, sequentially: [x(t_c) as a function of x0 | forced part]
        Xs = np.empty((C + 1, n, n + 1))
        Xs[0, :, :n] = np.eye(n)
        Xs[0, :, n] = 0.0
        for c in range(C):
            Xs[c + 1] = Pw[c, K] @ Xs[c]
            Xs[c + 1, :, n] += Z[c, K]
        Yc = np.einsum("cirn,cnm->cirm", Pw[:, :K][:, :, rows], Xs[:C])
        Yc[:, :, :, n] += Z[:, :K][:, :, rows]
        Yp = np.concatenate([Yc.reshape(C * K, len(rows), n + 1), Xs[C:, rows]])[:N]
        G = Yp[:, :, :n].transpose(1, 0, 2).reshape(len(rows) * N, n)
        R = self.problem.Ymeas.T.ravel() - Yp[:, :, n].T.ravel()
        if not self._pos_only and Bv is not None:
            # velocity channels: x = z + B_v r (B_v fixed on this path)
            R -= (Bv[rows] @ self._r).ravel()
        sol, *_ = np.linalg.lstsq(G, R, rcond=None)
        R = R - G @ sol
        return R.reshape(len(rows), N)

    def residual(self, p: Mapping[str, float]) -> FloatArray | None:
        """Residual (p, N) of the fast evaluation at ``p`` (cached), or ``None``."""
        ev = self.problem.evaluate(p)
        return None if ev is None else ev.R

    def drift_sensitivity(self, p: Mapping[str, float], names: list[str], t_ref: float
                          ) -> tuple[FloatArray, FloatArray] | None:
        """Sensitivities of the fitted channels to a constant change and to a linear drift.

        For each ``k`` in ``names``, with ``theta_k(t) = p_k exp(a) (1 + g (t - t_ref))``, the
        derivatives at ``a = g = 0`` of the predicted fitted channels with respect to ``a``
        (log units) and to ``g`` (1/s), the initial state refitted (the columns projected
        off the free-response regressors, as the least-squares initial state does). They
        are the responses of the linear sensitivity system ``s' = A s + f(t)`` from rest to
        ``f = p_k (dA/dtheta_k z(t) + dBz/dtheta_k r(t))`` and to ``(t - t_ref) f``, ``z``
        the fast evaluation's state trajectory at ``p`` (the simulator's ``z = x - B_v r``
        coordinates), simulated in the evaluation's modal form with the first-order hold
        of the exact discretisation. ``B_v`` must not depend on ``names`` (as for
        :meth:`drift_residual`).

        Parameters
        ----------
        p : mapping
            Parameters (SI), typically the constant fit's estimate.
        names : list of str
            Parameters whose sensitivities are wanted.
        t_ref : float
            Reference time of the drift (s; the window end).

        Returns
        -------
        (Ja, Jg) : tuple of ndarray, or None
            Each ``(p N, len(names))``, rows channel-major as :meth:`drift_residual`'s
            residual raveled; ``None`` when :attr:`drift_ok` is false, ``p`` is not on the
            fast path or ``B_v`` depends on one of ``names``.
        """
        if not self.drift_ok or not names:
            return None
        ev = self.problem.evaluate(p)
        if ev is None:
            return None
        nr = self._nr
        N = self._N
        h = self._hf
        vals = [float(p[k]) for k in self._names]
        A, B, Bz, _ = self.problem.state_space(vals)
        dA, dBz = [], []
        for k in names:
            i = self._names.index(k)
            eps = 1e-6
            v = list(vals)
            v[i] = vals[i] * (1.0 + eps)
            A1, B1, Bz1, _ = self.problem.state_space(v)
            if float(np.abs(B1[:, nr:] - B[:, nr:]).max()) > 1e-9 * (
                    float(np.abs(B[:, nr:]).max()) + 1e-300):
                return None  # a road-rate input that moves with the parameter
            # per unit log-parameter: theta dA/dtheta (affine maps: exact to rounding)
            dA.append((A1 - A) / eps)
            dBz.append((Bz1 - Bz) / eps)
        pat = ev.pat
        mm = ev.P.shape[0]
        V = ev.vr @ pat.sel_v  # (n, m) kept modes
        Vfull = np.concatenate([V, V[:, pat.pairs].conj()], axis=1)
        try:
            Vinv = np.linalg.inv(Vfull)[:mm]  # (m, n)
        except np.linalg.LinAlgError:
            return None
        lam = ((Vinv @ A) * V.T).sum(axis=1)  # eigenvalues of the kept modes
        z = (V * pat.fac) @ ev.modal(self._r)  # (n, N) complex, real part the state
        zr = z.real
        tt = self.problem.t - t_ref
        q = len(names)
        n = A.shape[0]
        # modal forcing (2 q, m, N): constant columns (per unit a) V^-1 (dA_k z + dBz_k r),
        # then the ramp's (per unit g), the constant ones times (t - t_ref); the small
        # products V^-1 dA_k, V^-1 dBz_k first, their real and imaginary parts in one real
        # product with [z; r]
        K = np.concatenate([np.stack([Vinv @ a for a in dA]).reshape(q * mm, n),
                            np.stack([Vinv @ b for b in dBz]).reshape(q * mm, nr)], axis=1)
        KX = np.concatenate([K.real, K.imag]) @ np.concatenate([zr, self._r])
        Bm = np.empty((2 * q, mm, N), dtype=complex)
        Bm.real[:q] = KX[:q * mm].reshape(q, mm, N)
        Bm.imag[:q] = KX[q * mm:].reshape(q, mm, N)
        np.multiply(Bm[:q], tt, out=Bm[q:])
        # first-order-hold weights per mode (as the fast evaluation's)
        _, g0, g1 = foh_weights(lam, h)
        # w[k] = E^k sum_{l<k} (g0 b[l] + g1 b[l+1]) E^-(l+1), w[0] = 0
        P = ev.P
        D = g0[None, :, None] * Bm[:, :, :-1] + g1[None, :, None] * Bm[:, :, 1:]
        W = np.zeros_like(Bm)
        W[:, :, 1:] = P[None, :, 1:] * np.cumsum(D / P[None, :, 1:], axis=-1)
        CV = (ev.vr[self._rows] @ pat.sel_cv)  # (p, m)
        S = np.matmul(CV, W).real  # (2 q, p, N)
        pch = CV.shape[0]
        Sf = S.reshape(S.shape[0], pch * N)
        # the initial state refitted: project off the free-response regressors (full
        # column rank: the fast evaluation checked their Gram matrix's condition number)
        T = CV.T[:, :, None] * P[:, None, :]
        pairs = pat.pairs
        G = np.concatenate([T.real, -T.imag[pairs]]).reshape(mm + pairs.size, pch * N)
        Qg = np.linalg.qr(G.T)[0]
        Sf = Sf - (Sf @ Qg) @ Qg.T
        if not np.isfinite(Sf).all():
            return None
        return np.ascontiguousarray(Sf[:q].T), np.ascontiguousarray(Sf[q:].T)

    def drift_ss(self, p: Mapping[str, float], rates: Mapping[str, float], t_ref: float,
                 chunk_s: float) -> float:
        """:meth:`normalized_ss` of the drifting window (``inf`` when it cannot be formed)."""
        try:
            R = self.drift_residual(p, rates, t_ref, chunk_s)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError, OverflowError):
            return math.inf
        if R is None:
            return math.inf
        r = R.ravel()
        v = float(r @ r) / self.problem.scale
        return v if math.isfinite(v) else math.inf

    def drift_stderr(self, p: Mapping[str, float], free: list[str], rates: Mapping[str, float],
                     t_ref: float, chunk_s: float, rel_step: float = 1e-4,
                     rate_prior_sd: float | None = None, R0: FloatArray | None = None
                     ) -> dict[str, float] | None:
        """Gauss-Newton standard errors (SI) of the free parameters at ``t_ref`` with the
        drift ``rates`` free as well (forward differences, noise per channel from the
        residual); ``rate_prior_sd`` (1/s) adds a
        prior of that standard deviation on each free rate. ``R0``: the residual at ``p``
        when already computed (as :meth:`drift_residual` returns it).
        """
        rates = dict(rates)

        def resid(q: Mapping[str, float], g: Mapping[str, float]) -> FloatArray | None:
            return self.drift_residual(q, g, t_ref, chunk_s)

        if R0 is None:
            R0 = resid(p, rates)
        if R0 is None:
            return None
        pch, N = R0.shape
        cols = []
        for k in free:
            q = dict(p)
            q[k] = p[k] * math.exp(rel_step)
            Rk = resid(q, rates)
            if Rk is None:
                return None
            cols.append(((Rk - R0) / rel_step).ravel())
        for k in rates:
            g = dict(rates)
            g[k] = rates[k] + rel_step
            Rk = resid(p, g)
            if Rk is None:
                return None
            cols.append(((Rk - R0) / rel_step).ravel())
        sig = np.sqrt((R0 * R0).sum(axis=1) / max(N - len(cols), 1))
        sig = np.where(sig > 0, sig, 1.0)
        J = (np.column_stack(cols).reshape(pch, N, -1) / sig[:, None, None]).reshape(pch * N, -1)
        H = J.T @ J
        if rate_prior_sd:
            nf = len(free)
            H[nf:, nf:] += np.eye(len(rates)) / rate_prior_sd ** 2
        try:
            cov = np.linalg.inv(H)
        except np.linalg.LinAlgError:
            return None
        return {k: float(p[k] * math.sqrt(max(float(cov[i, i]), 0.0)))
                for i, k in enumerate(free)}

    @staticmethod
    def _upper(n: int) -> FloatArray:
        """Upper-triangular 0/1 mask (n x n), cached for the process."""
        got = _UPPER.get(n)
        if got is None:
            got = _UPPER[n] = np.triu(np.ones((n, n)))
        return got
