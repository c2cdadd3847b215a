"""A monitor window's fit beyond its cost: stderr, Gauss-Newton steps, drifting parameters.

:class:`WindowFit` reuses the cached evaluations of the window's
:class:`~estimator.identify.OutputErrorProblem` (its fast path); where the fast path does not
apply (a gap, a non-uniform grid) the core's :func:`estimator.identify.finish` is used.
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
from estimator.identify.outputs import channel_kinds, output_maps
from estimator.identify.result import IdentResult
from suspid.models.base import FloatArray
from suspid.simulate import foh_weights

#: largest final-simplex edge (log units) and edge-matrix condition number (1-norm) for
#: which the Jacobian is the simplex's secant instead of forward differences
SECANT_MAX_EDGE = 0.02
SECANT_MAX_COND = 1e3
#: farthest (log units, per parameter) the Gauss-Newton steps go from Nelder-Mead's best vertex
GAUSS_NEWTON_MAX_STEP = 0.06

def small_inverse(M: FloatArray) -> tuple[FloatArray | None, float]:
    """Inverse of a small square matrix and its 1-norm condition number (closed form up to
    2x2, else LAPACK ``dgesv``); ``(None, inf)`` when ``M`` is singular or not finite."""
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
    """:func:`~estimator.identify.identifiability.assess` of a square QR factor; a 2x2 factor
    with well separated singular values is judged in closed form."""
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


def drift_cov(cols: FloatArray, R: FloatArray, n_free: int,
              rate_prior_sd: float | None) -> FloatArray | None:
    """Gauss-Newton covariance of the Jacobian ``cols`` (p N x n: the free parameters', then
    the rates' columns), each channel weighted by its noise in the residual ``R`` (p, N);
    ``rate_prior_sd`` (1/s) adds a prior on the rates. ``None`` when singular."""
    pch, N = R.shape
    sig = np.sqrt((R * R).sum(axis=1) / max(N - cols.shape[1], 1))
    sig = np.where(sig > 0, sig, 1.0)
    J = (cols.reshape(pch, N, -1) / sig[:, None, None]).reshape(pch * N, -1)
    H = J.T @ J
    if rate_prior_sd:
        H[n_free:, n_free:] += np.eye(H.shape[0] - n_free) / rate_prior_sd ** 2
    try:
        return np.asarray(np.linalg.inv(H), dtype=float)
    except np.linalg.LinAlgError:
        return None


@dataclass
class GaussNewton:
    """Outcome of :meth:`WindowFit.gauss_newton`."""

    params: dict[str, float] | None  # the parameters reached (SI); None: no step taken
    jacobian: FloatArray | None  # residual Jacobian (log-parameters) at the start
    nfev: int  # evaluations used


class WindowFit:
    """What a monitor window needs beyond its cost, on the window's ``problem`` (built with
    ``ride_heights=False``: the motion channels are compared)."""

    def __init__(self, problem: OutputErrorProblem) -> None:
        self.problem = problem
        m = problem.model
        self.model = m
        #: ``(free, p_hat, J)`` of the last fast :meth:`finish`: ``J`` (p N x n_free) the
        #: derivative of the predicted channels (channel-major) by the log-parameters
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

    def finish(self, params: Parameters, p_hat: Mapping[str, float], nfev: int,
               converged: bool, simplex: list[Mapping[str, float]] | None = None,
               rel_step: float = 1e-6, jacobian: FloatArray | None = None) -> IdentResult:
        """:func:`estimator.identify.finish` for a window at the estimate ``p_hat`` (SI).

        The same quantities with the evaluations reused: the Jacobian is the secant through
        Nelder-Mead's final ``simplex`` (parameter sets, best first) when its edges are at
        most :data:`SECANT_MAX_EDGE` and well conditioned, else ``jacobian`` (log-parameters,
        channel-major rows) when given, else forward differences of ``rel_step`` (log units).
        ``params`` gives the free/fixed split only.
        """
        free = params.free
        ev = self.problem.evaluate(p_hat)
        if ev is None or not free:
            return finish(self.problem, params, p_hat, nfev, converged, with_stderr=True)
        model = self.model
        pch, N = ev.R.shape
        r0 = ev.R.ravel()
        x0 = self.problem.initial_state(ev)
        # every measured model channel (rows), from the estimated x0
        Cm, Dm = output_maps(self._all_kind, ev.A, ev.B, self._nq)
        Yall = ((Cm @ ev.vr @ ev.pat.sel_cv @ ev.modal(self._r)).real
                + (Cm @ ev.B[:, self._nr:]) @ self._r + Dm @ self.problem.U.T)
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
        # the verdict needs only Jn's singular values and right vectors: those of its QR's R
        qr, _, _, info = _dgeqrf(Jn)
        small = np.triu(qr[:nf])
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
        """Up to ``steps`` chord Gauss-Newton steps from Nelder-Mead's best vertex ``p_hat`` (SI)
        on one forward-difference Jacobian (``rel_step``, log units), each within
        :data:`GAUSS_NEWTON_MAX_STEP` of ``p_hat`` and kept while it lowers the cost."""
        ev = self.problem.evaluate(p_hat)
        if ev is None or not free:
            return GaussNewton(None, None, 0)
        r = ev.R.ravel()
        J = self._forward_jacobian(free, p_hat, r, rel_step)
        nfev = len(free)
        if J is None:
            return GaussNewton(None, None, nfev)
        # the normal equations, formed once (cheaper than a QR of the tall J)
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
        """Residual Jacobian (log-parameters) by forward differences at ``p_hat`` (residual
        ``r0``); ``None`` when an evaluation leaves the fast path."""
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

    @property
    def drift_ok(self) -> bool:
        """Whether :meth:`drift_residual` applies (fast path, fitted channels are states)."""
        return bool(self.problem.fast and self.problem.state_rows)

    def drift_residual(self, p: Mapping[str, float], rates: Mapping[str, float],
                       t_ref: float, chunk_s: float) -> FloatArray | None:
        """Residual (p, N) of a window whose parameters drift linearly in time.

        ``theta_k(t) = p_k (1 + g_k (t - t_ref))`` for ``k`` in ``rates`` (1/s). ``A`` and
        ``Bz`` are taken at each chunk's (``chunk_s``) middle and discretised exactly with a
        first-order-hold road; the initial state is fitted by least squares. ``None`` when
        :attr:`drift_ok` is false, a chunk is not finite or a drifting parameter enters ``B_v``.
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
                # B_v is affine in the parameters: equal at the first and last chunk means
                # constant (a drifting tyre damping is not handled)
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
        """Sensitivities ``(Ja, Jg)`` of the fitted channels to a constant change and a drift.

        For ``k`` in ``names`` and ``theta_k(t) = p_k exp(a) (1 + g (t - t_ref))``, the
        derivatives at ``a = g = 0`` by ``a`` and ``g`` (1/s), each ``(p N, len(names))``
        channel-major, the initial state refitted; simulated in the fast evaluation's modal
        form. ``None`` off the fast path or when ``B_v`` depends on one of ``names``.
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
        # modal forcing (2 q, m, N): per unit a V^-1 (dA_k z + dBz_k r), per unit g the same
        # times (t - t_ref)
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
        # the initial state refitted: project off the free-response regressors
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
                     t_ref: float, chunk_s: float, rate_prior_sd: float | None, R0: FloatArray,
                     rel_step: float = 1e-4) -> dict[str, float] | None:
        """Gauss-Newton standard errors (SI) of ``free`` at ``t_ref`` with the drift ``rates``
        free too (forward differences); ``rate_prior_sd`` (1/s) adds a prior on each rate;
        ``R0`` the residual at ``p``."""
        rates = dict(rates)
        moved = ([(dict(p, **{k: p[k] * math.exp(rel_step)}), rates) for k in free]
                 + [(dict(p), dict(rates, **{k: rates[k] + rel_step})) for k in rates])
        cols = []
        for q, g in moved:
            Rk = self.drift_residual(q, g, t_ref, chunk_s)
            if Rk is None:
                return None
            cols.append(((Rk - R0) / rel_step).ravel())
        cov = drift_cov(np.column_stack(cols), R0, len(free), rate_prior_sd)
        if cov is None:
            return None
        return {k: float(p[k] * math.sqrt(max(float(cov[i, i]), 0.0)))
                for i, k in enumerate(free)}
