"""The filtered equation-error regression behind the data-driven start.

Every model is ``M q'' + C q' + K q = Fk r + Fc r'`` with matrices linear in the masses,
dampers and springs. Passing every signal through the same filter ``F_k = s^(k+2) / D(s)``,
``D(s) = (s^2 + 2 zeta w s + w^2)^2``, keeps the equation with no numerical
differentiation; the filter's transient (its four modes) is projected out. The
parameters that enter linearly follow from one least-squares problem; lengths are
searched with the linear ones solved at each point (variable projection).
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import expm

from suspid.io.csvio import Measurement
from suspid.models.base import FloatArray, SuspensionModel

#: damping ratio of the filter's double pole pair
FILTER_ZETA = 0.8
#: longest run of missing samples bridged by linear interpolation; a longer gap is cut out
FILL_MAX = 3
#: shortest stretch of valid samples between cut gaps the regression keeps
SEGMENT_MIN = 16


def _filter_bank(w: float, h: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """FOH discretisation ``(Phi, G1, G2, d)`` of ``1/D(s)`` in controllable form."""
    z = FILTER_ZETA
    # D(s) = (s^2 + 2 z w s + w^2)^2 = s^4 + d3 s^3 + d2 s^2 + d1 s + d0
    d = np.array([w ** 4, 4 * z * w ** 3, 2 * w ** 2 + 4 * z * z * w * w, 4 * z * w])
    A = np.zeros((4, 4))
    A[:3, 1:] = np.eye(3)
    A[3] = -d
    aug = np.zeros((6, 6))
    aug[:4, :4] = A
    aug[3, 4] = 1.0  # b = e4
    aug[4, 5] = 1.0  # u' = slope (first-order hold)
    E = expm(aug * h)
    return E[:4, :4], E[:4, 4], E[:4, 5], d


#: ``(Pb, T, Fh, d)`` of :func:`_impulse_responses` (``Fh`` complex)
_Responses = tuple[FloatArray, FloatArray, NDArray[np.complex128], FloatArray]
#: impulse responses of the filter already computed, ``(w, h, N) -> _impulse_responses``
_RESPONSES: dict[tuple[float, float, int], "_Responses"] = {}
#: how many of them are kept
_RESPONSES_KEPT = 16


def _impulse_responses(w: float, h: float, N: int) -> _Responses:
    """``(Pb, T, Fh, d)`` of the filter at ``w`` (rad/s), step ``h`` (s), ``N`` samples.

    ``Pb[n] = Phi^n b``, ``T[n]`` the first row of ``Phi^n``, ``Fh`` the FFT of the impulse
    response and ``d`` the denominator: independent of the record's values, so kept.
    """
    key = (float(w), float(h), int(N))
    hit = _RESPONSES.get(key)
    if hit is not None:
        return hit
    Phi, G1, G2, d = _filter_bank(w, h)
    a, b = G1 - G2 / h, G2 / h
    Pa = np.empty((N, 4))  # Phi^i a
    Pb = np.empty((N, 4))  # Phi^i b
    T = np.empty((N, 4))  # first row of Phi^n
    va, vb, row = a.copy(), b.copy(), np.eye(4)[0]
    for n in range(N):
        Pa[n], Pb[n], T[n] = va, vb, row
        va, vb, row = Phi @ va, Phi @ vb, row @ Phi
    H = Pb.copy()
    H[1:] += Pa[:-1]
    L = 1 << int(np.ceil(np.log2(2 * N)))
    Fh = np.fft.rfft(H, L, axis=0)
    for arr in (Pb, T, Fh, d):
        arr.flags.writeable = False
    if len(_RESPONSES) >= _RESPONSES_KEPT:
        _RESPONSES.pop(next(iter(_RESPONSES)))
    _RESPONSES[key] = (Pb, T, Fh, d)
    return Pb, T, Fh, d


#: filter products already computed, ``(w, h, N) -> _noise_products``
_PRODUCTS: dict[tuple[float, float, int], FloatArray] = {}


def _noise_products(w: float, h: float, N: int) -> FloatArray:
    """``P[a, b]``: the expected sum over the kept samples of ``(F_a e)(F_b e)``, a, b = 0..4.

    ``e`` is unit white noise; kept per bandwidth ``w`` (rad/s), step ``h`` (s) and length.
    """
    key = (float(w), float(h), int(N))
    hit = _PRODUCTS.get(key)
    if hit is not None:
        return hit
    _, _, Fh, d = _impulse_responses(w, h, N)
    L = 1 << int(np.ceil(np.log2(2 * N)))
    H = np.empty((N, 5))
    H[:, :4] = np.fft.irfft(Fh, L, axis=0)[:N]
    H[:, 4] = -H[:, :4] @ d  # s^4/D = 1 - (d0 + d1 s + d2 s^2 + d3 s^3)/D
    H[0, 4] += 1.0
    c = np.maximum(N - np.maximum(np.arange(N), 2), 0).astype(float)
    P = (H * c[:, None]).T @ H
    P.flags.writeable = False
    if len(_PRODUCTS) >= _RESPONSES_KEPT:
        _PRODUCTS.pop(next(iter(_PRODUCTS)))
    _PRODUCTS[key] = P
    return P


#: white-noise variance (:func:`_noise_variance`) relative to a channel's variance below
#: which the channel counts as noise-free (noise-free records measure up to 2e-10)
NOISE_NEGLIGIBLE = 1e-8


def _noise_variance(y: FloatArray) -> float:
    """Variance of white noise in ``y`` from its fourth differences (``mean(d4^2) / 70``).

    Differences that touch a missing sample are left out; a response sampled well above
    its modes hardly enters them.
    """
    d4 = np.diff(y, 4)
    d4 = d4[np.isfinite(d4)]  # a fourth difference that touches a missing sample: none
    return float(d4 @ d4) / (70.0 * d4.size) if d4.size else 0.0


def _filter(U: FloatArray, w: float, h: float) -> tuple[FloatArray, FloatArray]:
    """Filter the columns of ``U`` (N, m): outputs ``s^k / D`` for k = 0..4 and the modes.

    A convolution with the FOH recursion's impulse response, by FFT.

    Returns
    -------
    Y : ndarray, shape (5, N, m)
        ``Y[k]`` is ``s^k / D(s)`` applied to each column (zero initial filter state).
    T : ndarray, shape (N, 4)
        The filter's free-response functions (the transient's span).
    """
    N, m = U.shape
    Pb, T, Fh, d = _impulse_responses(w, h, N)
    L = 1 << int(np.ceil(np.log2(2 * N)))
    Fu = np.fft.rfft(U, L, axis=0)
    Y = np.empty((5, N, m))
    for i in range(4):
        Y[i] = np.fft.irfft(Fh[:, i:i + 1] * Fu, L, axis=0)[:N] - np.outer(Pb[:, i], U[0])
    Y[4] = U - np.einsum("j,jnm->nm", d, Y[:4])
    return Y, T


def _segments(missing: NDArray[np.bool_]) -> list[tuple[int, int, int]]:
    """Stretches of the record the regression keeps, around the long gaps in ``missing``.

    A run of more than ``FILL_MAX`` missing samples is a gap: each stretch between gaps is
    a record of its own (its first two rows dropped, its own transient projected out);
    one shorter than ``SEGMENT_MIN`` samples is dropped.

    Parameters
    ----------
    missing : ndarray of bool, shape (N,)
        Samples where some channel the regression uses is missing.

    Returns
    -------
    list of (origin, lo, hi)
        Rows ``lo:hi`` kept, the transient spanned by ``T[lo - origin:hi - origin]``; the
        whole record ``[(0, 2, N)]`` when there is no gap or no stretch left.
    """
    N = missing.size
    edges = np.flatnonzero(np.diff(np.concatenate([[0], missing.astype(np.int8), [0]])))
    gaps = [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2]) if b - a > FILL_MAX]
    if not gaps:
        return [(0, 2, N)]
    out: list[tuple[int, int, int]] = []
    origin, lo = 0, 2
    for a, b in gaps:
        if a - lo >= SEGMENT_MIN:
            out.append((origin, lo, a))
        origin, lo = b, b + 2
    if N - lo >= SEGMENT_MIN:
        out.append((origin, lo, N))
    return out if out else [(0, 2, N)]


def _fill(y: FloatArray, t: FloatArray) -> FloatArray | None:
    """Linear interpolation over missing samples (None if fewer than half are present)."""
    ok = np.isfinite(y)
    if ok.sum() < max(10, y.size // 2):
        return None
    if ok.all():
        return y
    return np.interp(t, t[ok], y[ok])


class _Regression:
    """Filtered signals of one record, ready for the equation-error least squares."""

    def __init__(self, model: SuspensionModel, meas: Measurement, t: FloatArray, h: float,
                 U: FloatArray, w: float, noise: bool = False,
                 segments: list[tuple[int, int, int]] | None = None) -> None:
        """Filter the record's channels at ``w`` (rad/s), step ``h`` (s).

        ``segments`` (:func:`_segments`) fixes the rows kept; default: from the channels' gaps.
        """
        nq = len(model.coords)
        nr = len(model.roads)
        cols: list[FloatArray] = []
        raw: list[FloatArray] = []
        plan: list[list[tuple[int, int]]] = []  # per coordinate: (column, derivative order)
        for c in model.coords:
            srcs = []
            for order, name in enumerate((c, f"{c}_dot", f"{c}_ddot")):
                if name in meas.measured:
                    y0 = np.asarray(meas.measured[name], dtype=float)
                    y = _fill(y0, t)
                    if y is not None:
                        srcs.append((len(cols), order))
                        cols.append(y)
                        raw.append(y0)
            plan.append(srcs[:2])  # at most two sources, combined
        used = [raw[col] for srcs in plan for col, _ in srcs]
        missing = np.zeros(t.size, dtype=bool)
        for y0 in used:
            missing |= np.isnan(y0)
        self.segments = segments if segments is not None else _segments(missing)
        self._raw = raw
        self.missing = [c for c, s in zip(model.coords, plan) if not s]
        self._plan = plan
        self._nq, self._nr, self._nmeas = nq, nr, len(cols)
        self._w, self._h = w, h
        self._sig2: list[float] | None = None
        for j in range(nr):
            cols.append(U[:, j])
        self._cols = cols
        self._Y, self._T = _filter(np.column_stack(cols), w, h)
        self._build(noise)

    def with_noise(self) -> "_Regression":
        """A copy set up for the noise-compensated fit (``B`` and the noise weights)."""
        out = object.__new__(_Regression)
        out.__dict__.update(self.__dict__)
        out._build(True, signals=any(len(s) > 1 for s in self._plan))
        return out

    def _build(self, noise: bool, signals: bool = True) -> None:
        """``Q``, ``R``, ``S``, ``G`` (and with ``noise`` the noise share ``B``).

        ``signals`` False keeps the present ``Q`` ... ``G`` and adds ``B`` only.
        """
        nq, nr, plan, Y, T = self._nq, self._nr, self._plan, self._Y, self._T
        N = T.shape[0]
        P = _noise_products(self._w, self._h, N) if noise else np.zeros((5, 5))
        kept = sum(hi - lo for _, lo, hi in self.segments)
        if noise and kept != N - 2:
            # fewer rows kept (gaps cut out): the noise share shrinks with their number
            P = P * (kept / (N - 2))
        if noise and self._sig2 is None:
            self._sig2 = [_noise_variance(y) for y in self._raw]
        sig2 = self._sig2 if noise and self._sig2 is not None else [0.0] * self._nmeas
        # weight of each source of coordinate i in F_k q: equal, or with ``noise`` inversely
        # as the noise each carries (any weights summing to one keep the equation)
        wt = np.zeros((nq, 3, 2))
        for i, srcs in enumerate(plan):
            for k in range(3):
                v = np.array([sig2[col] * P[k + 2 - o, k + 2 - o] for col, o in srcs])
                if noise and len(srcs) > 1 and np.all(v > 0):
                    wt[i, k, :len(srcs)] = (1.0 / v) / np.sum(1.0 / v)
                else:
                    wt[i, k, :len(srcs)] = 1.0 / max(len(srcs), 1)
        if signals:
            # Q[k] (nq, N): F_k q = s^(k+2)/D q from a position, s^(k+1)/D from a velocity, ...
            self.Q = np.zeros((3, nq, N))
            for i, srcs in enumerate(plan):
                for si, (col, order) in enumerate(srcs):
                    for k in range(3):
                        self.Q[k, i] += Y[k + 2 - order, :, col] * wt[i, k, si]
            self.R = np.zeros((2, nr, N))
            for j in range(nr):
                for k in range(2):
                    self.R[k, j] = Y[k + 2, :, self._nmeas + j]
            # project out the transient and the first samples, per stretch between gaps
            bases = [(slice(lo, hi), np.linalg.qr(T[lo - origin:hi - origin])[0])
                     for origin, lo, hi in self.segments]

            def proj(X: FloatArray) -> FloatArray:
                parts = []
                for keep, Tq in bases:
                    Xk = X[..., keep]
                    parts.append(Xk - (Xk @ Tq) @ Tq.T)
                return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=-1)
            self.Q = proj(self.Q)
            self.R = proj(self.R)
            self.S = np.concatenate([self.Q[2], self.Q[1], self.Q[0], self.R[0], self.R[1]], axis=0)
            self.G = self.S @ self.S.T  # Gram matrix of the filtered signals: all the LS needs
        #: with ``noise``: the expected share of white measurement noise in ``G`` (rows
        #: F_2 q, F_1 q, F_0 q of each coordinate; the road is known exactly)
        self.B: FloatArray | None = None
        if noise:
            ns = self.S.shape[0]
            B = np.zeros((ns, ns))
            for i, srcs in enumerate(plan):
                for si, (col, o) in enumerate(srcs):
                    for k in range(3):
                        for kk in range(3):
                            B[(2 - k) * nq + i, (2 - kk) * nq + i] += (
                                sig2[col] * wt[i, k, si] * wt[i, kk, si] * P[k + 2 - o, kk + 2 - o])
            self.B = B
        self.iv = False  # True: G pairs instruments with the signals (not symmetric)

    def with_instruments(self, inst: "_Regression") -> "_Regression":
        """A copy whose normal equations use ``inst``'s signals as instruments."""
        out = object.__new__(_Regression)
        out.__dict__.update(self.__dict__)
        out.G = inst.S @ self.S.T
        out.iv = True
        out.B = None
        return out

    @staticmethod
    def coef(mats: tuple[FloatArray, ...]) -> FloatArray:
        """Coefficients (nq, n_signals) of ``M F2q + C F1q + K F0q - Fk F0r - Fc F1r``."""
        M, C, K, Fk, Fc = mats
        return np.hstack([M, C, K, -Fk, -Fc])

    def norms(self, coef: FloatArray) -> FloatArray:
        """Norm of each equation's residual for coefficients ``coef``."""
        return np.sqrt(np.maximum(np.einsum("is,st,it->i", coef, self.G, coef), 0.0))


def _monomials(eta: FloatArray) -> FloatArray:
    """``1, eta_i, eta_i eta_j (i <= j)``: the monomials of degree <= 2."""
    n = eta.size
    quad = [eta[i] * eta[j] for i in range(n) for j in range(i, n)]
    return np.concatenate([[1.0], eta, quad])


def _monomial_slopes(eta: FloatArray) -> FloatArray:
    """``d monomial / d eta`` (rows as :func:`_monomials`, one column per length)."""
    n = eta.size
    rows = [np.zeros(n)] + [np.eye(n)[i] for i in range(n)]
    for i in range(n):
        for j in range(i, n):
            g = np.zeros(n)
            g[i] += eta[j]
            g[j] += eta[i]
            rows.append(g)
    return np.array(rows).reshape(-1, n)


def _coef_poly(model: SuspensionModel, base: Mapping[str, float], lin: list[str],
               nonlin: list[str]) -> tuple[FloatArray, FloatArray] | None:
    """The equation coefficients as a polynomial of the lengths.

    ``K[j, m]``: ``j`` = 0 the part no linear parameter multiplies, ``j`` = 1.. each of
    ``lin``, ``m`` the monomials (:func:`_monomials`), so that
    ``coef = sum_j theta_j sum_m phi_m(eta) K[j, m]``; and the largest coefficient per ``j``.
    ``None`` when the dependence is not a polynomial of degree <= 2.
    """
    rng = np.random.default_rng(7)
    x0 = np.array([base[k] for k in nonlin])
    pts = [x0 * np.exp(rng.normal(0.0, 0.5, x0.size)) for _ in range(3 * (x0.size + 1) ** 2)]

    def coef_of(j: str | None, eta: FloatArray) -> FloatArray:
        p = {**base, **dict(zip(nonlin, eta)), **{k: 0.0 for k in lin}}
        c0 = _Regression.coef(model.matrices(p))
        return c0 if j is None else _Regression.coef(model.matrices({**p, j: 1.0})) - c0

    Phi = np.array([_monomials(e) for e in pts])
    shape = coef_of(None, x0).shape
    K = np.empty((len(lin) + 1, Phi.shape[1]) + shape)
    vmax = np.empty(len(lin) + 1)
    for ji, j in enumerate([None, *lin]):
        vals = np.array([coef_of(j, e).ravel() for e in pts])
        P, *_ = np.linalg.lstsq(Phi[:-1], vals[:-1], rcond=None)
        if not np.allclose(Phi[-1] @ P, vals[-1], rtol=1e-8, atol=1e-10 * (1 + np.abs(vals).max())):
            return None
        K[ji] = P.reshape((-1,) + shape)
        vmax[ji] = np.abs(vals).max()
    return K, vmax


def _normal_equations(reg: "_Regression", Cs: FloatArray, b: FloatArray
                      ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """``A'A``, ``A'b``, the column scales ``d`` and ``A'A`` scaled by them, through ``reg.G``."""
    GC = np.einsum("jis,st->jit", Cs, reg.G)
    AtA = np.einsum("jit,lit->jl", GC, Cs)
    d = np.sqrt(np.where(np.abs(np.diag(AtA)) > 0, np.abs(np.diag(AtA)), 1.0))
    return AtA, np.einsum("jit,it->j", GC, b), d, AtA / np.outer(d, d)


def _lifted_seed(reg: "_Regression", model: SuspensionModel, base: Mapping[str, float],
                 lin: list[str], nonlin: list[str], wts: FloatArray) -> FloatArray | None:
    """Log-factors of the nonlinear parameters from the lifted linear problem.

    Each product of a linear parameter and a monomial of the lengths is its own unknown;
    the lengths follow as ratios ``(theta a) / theta``. ``None`` when not polynomial or
    no ratio is determined.
    """
    x0 = np.array([base[k] for k in nonlin])
    poly = _coef_poly(model, base, lin, nonlin)
    if poly is None:
        return None
    K, vmax = poly
    cols: list[FloatArray] = []
    tags: list[tuple[str | None, int]] = []
    b = np.zeros(K.shape[2:])
    for ji, j in enumerate([None, *lin]):
        for mi in range(K.shape[1]):
            cm = K[ji, mi]
            if np.max(np.abs(cm)) <= 1e-12 * (1 + vmax[ji]):
                continue
            if j is None and mi == 0:
                b = cm
            else:
                cols.append(cm * wts[:, None])
                tags.append((j, mi))
    if not cols:
        return None
    b = b * wts[:, None]
    _, Atb, d, H = _normal_equations(reg, np.stack(cols), b)
    if reg.iv:  # instrumental variables: a square, non-symmetric system
        z = np.linalg.lstsq(H, -Atb / d, rcond=1e-12)[0] / d
    else:
        ev, V = np.linalg.eigh(H)
        keep = ev > 1e-12 * ev[-1]
        z = (V[:, keep] @ ((V[:, keep].T @ (-Atb / d)) / ev[keep])) / d
    val = dict(zip(tags, z))
    out = []
    for i in range(x0.size):
        ratios = [val[(j, 1 + i)] / val[(j, 0)] for j in lin
                  if (j, 0) in val and (j, 1 + i) in val and val[(j, 0)] > 0]
        ratios = [r for r in ratios if r > 0]
        if not ratios:
            return None
        out.append(math.log(float(np.median(ratios)) / x0[i]))
    return np.array(out)


def _split_linear(model: SuspensionModel, base: Mapping[str, float], free: list[str]
                  ) -> tuple[list[str], list[str]]:
    """Free parameters that enter the matrices linearly (jointly), and the others."""
    def mats(p: Mapping[str, float]) -> FloatArray:
        return np.concatenate([np.ravel(a) for a in model.matrices(p)])

    lin: list[str] = []
    for k in free:
        vals = [mats({**base, k: base[k] * f}) for f in (1.0, 2.0, 3.5)]
        d1, d2 = vals[1] - vals[0], vals[2] - vals[0]
        if np.allclose(d2, 2.5 * d1, rtol=1e-9, atol=1e-12 * (1 + np.max(np.abs(vals[0])))):
            lin.append(k)
    if lin:  # joint check: affine in all of them at once
        p1 = {**base, **{k: base[k] * 1.7 for k in lin}}
        rec = mats(base) + sum(mats({**base, k: base[k] * 1.7}) - mats(base) for k in lin)
        if not np.allclose(mats(p1), rec, rtol=1e-9, atol=1e-12 * (1 + np.max(np.abs(rec)))):
            lin = []
    return lin, [k for k in free if k not in lin]


def _equation_weights(reg: "_Regression", model: SuspensionModel, p: Mapping[str, float]
                      ) -> FloatArray:
    """Weight of each equation in :func:`_solve_linear`: one over the norm of its mass term at ``p``."""
    mats = model.matrices(p)
    mk = reg.norms(reg.coef(mats))
    mass_term = reg.norms(reg.coef((mats[0],) + tuple(np.zeros_like(a) for a in mats[1:])))
    scale = np.where(mass_term > 0, mass_term, mk)
    return 1.0 / np.where(scale > 0, scale, 1.0)


def _solve_linear(reg: _Regression, model: SuspensionModel, p: Mapping[str, float],
                  lin: list[str], wts: FloatArray) -> tuple[FloatArray, float, float]:
    """Linear least squares for ``lin`` at the other values of ``p`` (normal equations).

    Returns ``(theta, relative residual, relative smallest singular value)``.
    """
    ones = {**p, **{k: 1.0 for k in lin}}
    c1 = reg.coef(model.matrices(ones)) * wts[:, None]
    cols = [reg.coef(model.matrices({**ones, k: 2.0})) * wts[:, None] - c1 for k in lin]
    b = c1 - sum(cols)  # the part that does not depend on lin
    AtA, Atb, d, H = _normal_equations(reg, np.stack(cols), b)  # cols: (nl, nq, ns)
    btb = float(np.einsum("is,st,it->", b, reg.G, b))
    if reg.iv:  # instrumental variables: a square, non-symmetric system
        sol, *_ = np.linalg.lstsq(H, -Atb / d, rcond=1e-12)
        sv = np.linalg.svd(H, compute_uv=False)
        return sol / d, 0.0, float(sv[-1] / sv[0]) if sv[0] > 0 else 0.0
    ev, V = np.linalg.eigh(H)
    if ev[-1] <= 0:
        return np.zeros(len(lin)), 1.0, 0.0
    rel_sv = float(math.sqrt(max(ev[0], 0.0) / ev[-1]))
    if btb <= 1e-24 * float(np.sum(AtA)):
        # homogeneous: every scale-setting parameter is free; take the null vector
        theta = V[:, 0] / d
        theta = theta * np.sign(np.sum(theta))
        rel_sv = float(math.sqrt(max(ev[1], 0.0) / ev[-1])) if ev.size > 1 else 1.0
        return theta, float(math.sqrt(max(ev[0], 0.0) / ev[-1])), rel_sv
    keep = ev > 1e-13 * ev[-1]
    sol = V[:, keep] @ ((V[:, keep].T @ (-Atb / d)) / ev[keep])
    theta = sol / d
    res2 = btb + 2 * float(Atb @ theta) + float(theta @ AtA @ theta)
    return theta, math.sqrt(max(res2, 0.0) / btb) if btb > 0 else 0.0, rel_sv
