"""Starting values from the record itself: a filtered equation-error least-squares fit.

Every model is ``M q'' + C q' + K q = Fk r + Fc r'`` with matrices *linear* in the masses,
dampers and springs. Passing every signal through the same linear filter keeps the
equation (the filter commutes with it), so with ``F_k = s^(k+2) / D(s)`` applied to a
position (``s^(k+1)/D`` to a velocity, ``s^k/D`` to an acceleration) and
``D(s) = (s^2 + 2 zeta w s + w^2)^2`` the filtered equation

    M F_2 q + C F_1 q + K F_0 q - Fk F_0 r - Fc F_1 r = transient

holds for any measured channel set that has one channel per coordinate, with no numerical
differentiation. The transient (the filter's own free response to the record's start) is a
combination of the filter's four modes and is projected out. The free parameters that
enter linearly follow from one linear least-squares problem given the known ones (masses,
inertia, geometry); parameters that do not enter linearly (lengths) are searched on a
log grid with the linear ones solved at each point (variable projection) and refined by
Nelder-Mead. Several filter bandwidths are tried and the estimate whose *output-error*
cost is lowest wins, so the choice adapts to where the record has its signal and its noise.

The estimate needs neither a starting guess nor derivatives; it cannot apply when a
coordinate has no measured channel at all (then the equations hold an unmeasured signal),
when the time grid is not uniform, or when the record holds too little motion to separate
the parameters (rank-deficient regression); the reason is reported and the caller falls
back to its other starts. With measurement noise least squares is biased (the noisy
channels are the regressors: errors in variables); where it does not explain the record
exactly, each equation's residual over the share white noise gives it (known from the
filters and each channel's noise variance) is minimised as well (:func:`_ratio_fit`), and
the lower output-error cost wins. Either way it is only a start: Nelder-Mead and the
polish refine it on the output-error cost.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import expm

from estimator.identify.params import Parameters
from estimator.identify.problem import OutputErrorProblem
from estimator.identify.profile import SIGMAS, apply_bands
from estimator.identify.result import IdentResult
from estimator.identify.simplex import nelder_mead
from suspid.errors import UsageError
from suspid.io.csvio import Measurement
from suspid.models.base import FloatArray, SuspensionModel, Twin
from suspid.simulate import simulate_states, uniform_step

#: damping ratio of the filter's double pole pair
FILTER_ZETA = 0.8
#: grid factors (relative to the start value) for parameters that enter nonlinearly
NONLIN_GRID = np.exp(np.linspace(math.log(0.05), math.log(20.0), 21))
#: normalised output-error cost below which an estimate is taken as exact (no further bandwidth)
EXACT_COST = 1e-7
#: floor of an estimate relative to the geometric mean of the others of its kind
FLOOR = 0.02
#: relative residual of the equation-error fit above which, when the equation weights at the
#: documented defaults of the free masses differ from those at the start values by more than
#: ``REWEIGHT_FACTOR`` in some equation, the fit is solved with those weights as well (start
#: values decades off, e.g. a free mass given at 1e-6x its value)
REWEIGHT_REL = 0.5
REWEIGHT_FACTOR = 30.0
#: longest run of missing samples of a channel the data-driven start bridges by linear
#: interpolation (a lost frame or three); a longer gap is cut out of its regression
#: (:func:`_segments`)
FILL_MAX = 3
#: shortest stretch of valid samples between cut gaps the regression keeps
SEGMENT_MIN = 16
#: smallest relative singular value of the regression accepted as "determined"
RANK_TOL = 1e-9
#: the noise-compensated fit (:func:`_ratio_fit`) stays within ``exp(RATIO_SPAN)`` of its
#: first start (a start outside that box: of that start)
RATIO_SPAN = 8.0
#: iterations of each of its BFGS runs
RATIO_ITER = 200
#: its stopping tolerance: the largest gradient component (of the mean ratio, ~1 at the
#: truth, in the logarithms of the values)
RATIO_GTOL = 1e-6


@dataclass
class StartEstimate:
    """A data-driven starting point.

    Attributes
    ----------
    values : dict
        Free parameter -> estimate (SI); empty when the method could not apply.
    reason : str or None
        Why no estimate was made (``None`` when ``values`` is filled).
    bandwidth_hz : float
        Filter bandwidth of the chosen estimate (Hz).
    cost : float
        Normalised output-error cost at the estimate (1 = no fit).
    notes : list of str
        Adjustments made (e.g. a negative estimate replaced by a small positive value).
    undetermined : list of str
        Parameters whose estimate was not usable and was replaced by a floor value.
    """

    values: dict[str, float] = field(default_factory=dict)
    reason: str | None = None
    bandwidth_hz: float = float("nan")
    cost: float = float("inf")
    notes: list[str] = field(default_factory=list)
    undetermined: list[str] = field(default_factory=list)


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
#: how many of them are kept (the bandwidths of a few records' sample rates and lengths)
_RESPONSES_KEPT = 16


def _impulse_responses(w: float, h: float, N: int) -> _Responses:
    """``(Pb, T, Fh, d)`` of the filter at ``w`` (rad/s), step ``h`` (s), ``N`` samples.

    ``Pb[n] = Phi^n b``, ``T[n]`` the first row of ``Phi^n``, ``Fh`` the FFT of the impulse
    response ``H`` (see :func:`_filter`) and ``d`` the filter's denominator. They depend on
    neither the record's values nor the model, so every record of one sample rate and length
    (the bandwidths tried, the instrumental-variable iterations at the chosen one, every row
    of a design) shares them: computed once by the same recursion and kept (read-only).
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

    ``F_a`` is ``s^a / D(s)`` as :func:`_filter` applies it to a record of ``N`` samples and
    ``e`` unit white noise: ``sum_m c_m h_a[m] h_b[m]`` with ``h_a`` the impulse response and
    ``c_m`` the number of kept samples (from the third) at least ``m`` after the record's
    start. Computed once per bandwidth ``w`` (rad/s), step ``h`` (s) and length and kept.
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


#: white-noise variance (from :func:`_noise_variance`), relative to a channel's variance,
#: below which the channel counts as noise-free (noise std 1e-4 of the signal's: the bias
#: it puts in the estimate is ~1e-8). Noise-free design records measure up to 2e-10, the
#: seed's bump at 1 kHz 2e-12; noise at 0.001 sigma 1e-6.
NOISE_NEGLIGIBLE = 1e-8


def _noise_variance(y: FloatArray) -> float:
    """Variance of white noise in ``y`` from its fourth differences (``mean(d4^2) / 70``).

    Differences that touch a missing (NaN) sample are left out.

    A response of the model sampled well above its modes hardly enters them (a mode at a
    tenth of the sampling rate passes ``(2 sin(pi/10))^8`` = 2 % of its variance).
    """
    d4 = np.diff(y, 4)
    d4 = d4[np.isfinite(d4)]  # a fourth difference that touches a missing sample: none
    return float(d4 @ d4) / (70.0 * d4.size) if d4.size else 0.0


def _filter(U: FloatArray, w: float, h: float) -> tuple[FloatArray, FloatArray]:
    """Filter the columns of ``U`` (N, m): outputs ``s^k / D`` for k = 0..4 and the modes.

    The recursion ``z[n+1] = Phi z[n] + a u[n] + b u[n+1]`` (zero state before the record,
    ``a = G1 - G2/h``, ``b = G2/h``) is a convolution with the impulse response
    ``Phi^(i-1) a + Phi^i b``, less ``Phi^n b u[0]`` (the record has no sample before
    ``u[0]``); the responses come from one loop over 4 x 4 products
    (:func:`_impulse_responses`, computed once per bandwidth, step and length) and the
    convolution from an FFT of every column at once.

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

    A run of more than ``FILL_MAX`` missing samples is a gap: the linear interpolation
    that bridges it is no measurement, and the filters would carry its error on into the
    samples after it. Each stretch between gaps is taken as a record of its own: its rows
    (less the first two, as at the record's start) are kept and the filter's free response
    from its start is projected out (every free response begun before, the error the
    bridged gap left in the filter's state included, is one from there on). A stretch
    shorter than ``SEGMENT_MIN`` samples is dropped.

    Parameters
    ----------
    missing : ndarray of bool, shape (N,)
        Samples where some channel the regression uses is missing.

    Returns
    -------
    list of (origin, lo, hi)
        Rows ``lo:hi`` are kept, the transient there spanned by ``T[lo - origin:hi - origin]``
        (:func:`_impulse_responses`). The whole record is ``[(0, 2, N)]``; so is a record
        with no stretch left (then the gaps stay interpolated).
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

        ``segments`` (see :func:`_segments`) fixes the rows kept, e.g. those of the
        measured record for instruments simulated on its grid; default: from the gaps of
        the channels used.
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
        # the filtering is the same with or without the noise weights: done once, kept
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

        ``signals`` False keeps the present ``Q`` ... ``G`` (one source per coordinate:
        the noise weights are the plain ones) and adds ``B`` only.
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
        # weight of each source of coordinate i in F_k q: equal (averaged), or with
        # ``noise`` inversely as the noise each carries into F_k q (both are the same
        # signal, so any weights summing to one keep the equation)
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
            # project out the transient (the filter's modes) and the first samples, in
            # each stretch between gaps its own
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
    """The equation coefficients as a polynomial: ``K[j, m]`` with ``j`` = 0 the part no
    linear parameter multiplies, ``j`` = 1.. each of ``lin``, ``m`` the monomials of the
    lengths (:func:`_monomials`), so that ``coef = sum_j theta_j sum_m phi_m(eta) K[j, m]``
    (``theta_0 = 1``); and the largest coefficient met per ``j``. ``None`` when the
    dependence on the lengths is not a polynomial of degree <= 2.
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


def _lifted_seed(reg: "_Regression", model: SuspensionModel, base: Mapping[str, float],
                 lin: list[str], nonlin: list[str], wts: FloatArray) -> FloatArray | None:
    """Log-factors of the nonlinear parameters from the *lifted* linear problem.

    Lengths enter the matrices as polynomials (``c1 a1``, ``k1 a1**2``, ...). Each product
    of a linear parameter and a monomial of the lengths is taken as its own unknown, which
    makes the equation-error problem linear again; the lengths follow as ratios
    ``(theta a) / theta``. ``None`` when the dependence is not a polynomial of degree <= 2
    or no ratio is determined.
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
    Cs = np.stack(cols)
    GC = np.einsum("jis,st->jit", Cs, reg.G)
    AtA = np.einsum("jit,lit->jl", GC, Cs)
    Atb = np.einsum("jit,it->j", GC, b)
    d = np.sqrt(np.where(np.abs(np.diag(AtA)) > 0, np.abs(np.diag(AtA)), 1.0))
    H = AtA / np.outer(d, d)
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
    """Weight of each equation of motion in :func:`_solve_linear`: one over the norm of its
    mass term (of its whole filtered coefficient row where it has none) at the values ``p``."""
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
    Cs = np.stack(cols)  # (nl, nq, ns)
    GC = np.einsum("jis,st->jit", Cs, reg.G)
    AtA = np.einsum("jit,lit->jl", GC, Cs)
    Atb = np.einsum("jit,it->j", GC, b)
    btb = float(np.einsum("is,st,it->", b, reg.G, b))
    d = np.sqrt(np.where(np.abs(np.diag(AtA)) > 0, np.abs(np.diag(AtA)), 1.0))
    H = AtA / np.outer(d, d)
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


#: :func:`_bfgs` near the edge of its box: steps and relative decrease of a stalled run
EDGE_STALL = 10
EDGE_FTOL = 1e-6


def _bfgs(F: Callable[[FloatArray], tuple[float, FloatArray]], u0: FloatArray,
          iterations: int, gtol: float = 1e-6, span: float = math.inf
          ) -> tuple[float, FloatArray]:
    """Minimise ``F`` (value and gradient) by BFGS with a backtracking (Armijo) line search.

    Each line search starts at the full quasi-Newton step or, where that leaves the box
    ``|u| < span``, at the box's edge along it (a run may touch the edge and come back); a
    component on the edge whose way down points out of the box is held there. A full step
    after which the slope is still more than 0.9 of the first (Wolfe's curvature condition
    fails) is doubled while that lowers ``F``: without it a long curved valley is crawled
    along in the steps the first curvature estimate set (not after a backtracking, which
    found the step too long already). A run that has kept some
    ``|u_i|`` within 1 of the edge for ``EDGE_STALL`` steps while ``F`` fell by less than
    ``EDGE_FTOL`` of its value stops there: it crawls towards a minimum beyond the region
    searched (a run-away, not an estimate).

    Returns ``(value, point)`` of the lowest point met; stops when the gradient's largest
    component is below ``gtol``, stalled at the edge, when no step lowers ``F`` beyond its
    rounding (the gradient there may still read a little above ``gtol``: it is rounding
    too) or after ``iterations`` steps.
    """
    u = np.asarray(u0, dtype=float).copy()
    f, g = F(u)
    Hinv = np.eye(u.size)
    edge = span * (1.0 - 1e-9)
    near: list[float] = []  # values of the last steps ending within 1 of the edge
    for it in range(iterations):
        if not float(np.abs(g).max()) > gtol:
            break
        d = -Hinv @ g
        slope = float(g @ d)
        if not slope < 0:  # not a descent direction: restart from the gradient
            Hinv = np.eye(u.size)
            d, slope = -g, -float(g @ g)
        # the largest step inside the box; a component on the edge and pointing out is
        # held (the run slides along the edge)
        reach = math.inf
        for i, (ui, di) in enumerate(zip(u.tolist(), d.tolist())):
            room = (edge - ui) if di > 0 else (-edge - ui)
            if di != 0 and room / di <= 1e-10:
                d[i] = 0.0
            elif di != 0:
                reach = min(reach, room / di)
        slope = float(g @ d)
        if not slope < 0:  # on the edge, every way down points out of the box
            break
        full = step = min(1.0, reach)
        while step > 1e-10:
            un = u + step * d
            fn, gn = F(un)
            if fn <= f + 1e-4 * step * slope:
                break
            step *= 0.5
        else:
            break
        # the full step taken and the slope along it hardly less steep (the curvature
        # condition of Wolfe fails): the valley goes on, so the step doubles while it
        # keeps lowering F that much (a long, gently curved valley in a few steps)
        while step == full and step < reach and float(gn @ d) < 0.9 * slope:
            full = min(2.0 * step, reach)
            ut = u + full * d
            ft, gt = F(ut)
            if not ft <= f + 1e-4 * full * slope or not ft < fn:
                break
            step, un, fn, gn = full, ut, ft, gt
        sv, yv = un - u, gn - g
        sy = float(sv @ yv)
        if sy > 1e-12 * math.sqrt(float(sv @ sv) * float(yv @ yv)):
            if it == 0:  # the first step sets the scale (Nocedal & Wright 6.20)
                Hinv = np.eye(u.size) * sy / float(yv @ yv)
            # (I - rho s y') H (I - rho y s') + rho s s', rho = 1 / s'y, expanded
            Hy = Hinv @ yv
            Hinv = Hinv + ((sy + float(yv @ Hy)) / sy ** 2) * np.outer(sv, sv) \
                - (np.outer(Hy, sv) + np.outer(sv, Hy)) / sy
        lowered = f - fn > 8.0 * np.finfo(float).eps * abs(f)
        u, f, g = un, fn, gn
        if not lowered:  # the value changes only in its rounding: converged as far as it goes
            break
        near = near + [f] if float(np.max(np.abs(u))) > span - 1.0 else []
        if len(near) > EDGE_STALL:
            near = near[-EDGE_STALL - 1:]
            if near[0] - f <= EDGE_FTOL * max(abs(f), 1.0):
                break
    return f, u


def _ratio_fit(reg: _Regression, K: FloatArray, lin: list[str], nonlin: list[str],
               starts: Sequence[Mapping[str, float]]) -> list[dict[str, float]] | None:
    """Free parameters minimising each equation's residual over its noise share, averaged.

    With white measurement noise in the channels the filtered equation's residual at
    coefficients ``c_i`` (equation ``i``) has the expected sum of squares
    ``c_i' G0 c_i + c_i' B c_i`` (``G0`` the noise-free signals' Gram matrix, ``B`` the
    noise's share, :class:`_Regression` with ``noise``), so the ratio
    ``c_i' G c_i / c_i' B c_i`` is about 1 at the truth and larger elsewhere, as the record
    grows: unlike least squares (which minimises ``c' G c`` and so also the noise's share,
    pulling the estimate towards coefficients that pass little noise) its minimum is
    consistent (errors in variables; the maximum-likelihood criterion of one equation).
    The mean over the equations is minimised by BFGS on the logarithms of the values (all
    positive) from each of ``starts``, each run within ``exp(RATIO_SPAN)`` of the first
    start, or of its own start where that lies outside this box (analytic gradient through
    the polynomial ``K`` of :func:`_coef_poly`).

    Returns
    -------
    list of dict or None
        The end point of every run (free parameter -> value, SI), lowest mean ratio first,
        those within 1e-6 (relative) of an earlier one left out; ``None`` when no start
        gives a finite ratio. The caller chooses among them by the output-error cost: the
        ratio is about 1 at every minimum where the equations pass the noise alone,
        including spurious ones where some term's signal vanishes (a spring or damper
        near zero), so its value does not tell them apart.
    """
    if reg.B is None:
        return None
    nl = len(lin)
    free = lin + nonlin
    # the centre of the present run's box: the logarithms are taken from it
    x0 = np.ones(len(free))
    first = np.array([starts[0][k] for k in free]) if starts else x0.copy()
    big = 1e300
    # the coefficients are linear in z = theta (x) phi(eta), so each equation's two
    # quadratic forms are z' A_i z and z' D_i z: contracted with G and B once, here
    nj, nm, ni = K.shape[0], K.shape[1], K.shape[2]
    Kz = K.reshape(nj * nm, ni, K.shape[3])
    A = np.einsum("ais,st,bit->iab", Kz, reg.G, Kz)
    D = np.einsum("ais,st,bit->iab", Kz, reg.B, Kz)
    theta = np.ones(nl + 1)
    one = np.ones(1)

    def F(u: FloatArray) -> tuple[float, FloatArray]:
        if not (np.abs(u) < RATIO_SPAN).all():
            return big, np.zeros_like(u)
        x = x0 * np.exp(u)
        theta[1:] = x[:nl]
        eta = x[nl:]
        phi = _monomials(eta) if eta.size else one
        z = (theta[:, None] * phi).ravel()
        Az, Dz = A @ z, D @ z
        num, den = Az @ z, Dz @ z
        if not (den > 0).all():
            return big, np.zeros_like(u)
        q = num / den
        # dF/dz: the mean of dq_i/dz = 2 (A_i z - q_i D_i z) / den_i
        Gz = ((Az - q[:, None] * Dz) / den[:, None]).sum(axis=0).reshape(nj, nm)
        g = np.empty(u.size)
        g[:nl] = Gz[1:] @ phi
        if eta.size:
            g[nl:] = (theta @ Gz) @ _monomial_slopes(eta)
        return float(q.sum()) / ni, g * x * (2.0 / ni)

    ends: list[tuple[float, FloatArray]] = []
    for st in starts:
        v = np.array([st[k] for k in free])
        if not (np.all(v > 0) and np.all(np.isfinite(v))):
            continue
        # the box around the first start, or around this start when it lies outside that
        # box (a least-squares value floored far below the given start): such a start was
        # left out, although its run may be the one that reaches the truth's basin
        centre = first if np.all(first > 0) and np.all(
            np.abs(np.log(v / first)) < RATIO_SPAN) else v
        x0[:] = centre
        u0 = np.log(v / centre)
        if not F(u0)[0] < big:
            continue
        f, u = _bfgs(F, u0, RATIO_ITER, gtol=RATIO_GTOL, span=RATIO_SPAN)
        x = centre * np.exp(u)
        if math.isfinite(f) and f < big and not any(
                np.allclose(x, y, rtol=1e-6, atol=0.0) for _, y in ends):
            ends.append((f, x))
    if not ends:
        return None
    ends.sort(key=lambda fx: fx[0])
    return [{k: float(v) for k, v in zip(free, x)} for _, x in ends]


def _floored(model: SuspensionModel, base: Mapping[str, float], lin: list[str],
             vals: dict[str, float], what: str) -> tuple[dict[str, float], list[str], list[str]]:
    """``vals`` with each of ``lin`` below ``FLOOR`` x the geometric mean of the others of
    its kind (or not finite) raised to that floor: ``(values, floored names, notes)``.

    An estimate that small (least-squares or noise-compensated, named by ``what``) is not
    determined by the record (a spring or damper whose force the noise hides); as a start
    it would send the fit off along a flat direction, so it starts at the floor and is
    judged as undetermined.
    """
    out = dict(vals)
    floored: list[str] = []
    notes: list[str] = []
    ok = [k for k in lin if vals[k] > 0 and math.isfinite(vals[k])]
    for k in lin:
        kind = model.spec(k).kind
        same = [vals[j] for j in ok if model.spec(j).kind == kind and j != k]
        floor = FLOOR * (math.exp(float(np.mean(np.log(same)))) if same else base[k])
        if not (vals[k] >= floor and math.isfinite(vals[k])):
            notes.append(f"{k}: the {what} estimate {vals[k]:.3g} is not a usable "
                         f"positive value; started at {floor:.3g}")
            out[k] = floor
            floored.append(k)
    return out, floored, notes


def estimate_start(problem: OutputErrorProblem, params: Parameters,
                   bandwidths_hz: list[float] | None = None) -> StartEstimate:
    """Data-driven start of the free parameters of ``params`` for ``problem``'s record.

    Parameters
    ----------
    problem : OutputErrorProblem
        The record (any measured channel set with one channel per coordinate), its road
        and the cost used to rank candidate estimates.
    params : Parameters
        Fixed values (known masses, inertia, geometry) and, for parameters that do not
        enter the equations linearly, the centre of their search grid.
    bandwidths_hz : list of float, optional
        Filter bandwidths (Hz) tried in turn; default four, geometrically spaced from
        0.2 Hz to a fifth of Nyquist. The sweep ends early at an estimate that explains
        the record exactly (noise-free) or, on a noisy record, leaves only white noise
        (:func:`noise_floor_ratio` at most ``NOISE_FLOOR``); otherwise the estimate with
        the lowest output-error cost wins.

    Returns
    -------
    StartEstimate
        ``values`` holds the estimate; ``reason`` says why there is none.
    """
    model = problem.model
    meas = problem.meas
    free = params.free
    if not free:
        return StartEstimate(reason="no free parameter")
    t = problem.t
    h = uniform_step(t)
    if h is None:
        return StartEstimate(reason="the time grid is not uniform")
    base = params.valuesdict()
    lin, nonlin = _split_linear(model, base, free)
    if not lin:
        return StartEstimate(reason="no free parameter enters the equations of motion linearly")
    nyq = 0.5 / h
    # the coefficients as a polynomial of the free values, for the noise-compensated fit
    # (computed when first needed: a noise-free record does not need it)
    poly: list[tuple[FloatArray, FloatArray] | None] = []
    if bandwidths_hz is None:
        top = nyq / 5.0
        bandwidths_hz = [float(f) for f in np.geomspace(0.2, max(top, 0.3), 4)]
    best = StartEstimate(reason="no filter bandwidth gave a usable estimate")
    reasons: list[str] = []
    seeds: list[FloatArray] = []
    last_u: FloatArray | None = None
    best_reg: tuple[_Regression, FloatArray] | None = None
    # the noise compensation only where some channel carries measurable white noise: on a
    # noise-free record an inexact estimate is model or filter error, which it cannot fix
    noisy = any(_noise_variance(y) > NOISE_NEGLIGIBLE * float(np.nanvar(y))
                for y in (np.asarray(v, dtype=float) for v in meas.measured.values())
                if np.count_nonzero(~np.isnan(y)) > 4 and not np.any(np.isinf(y)))
    for fc in bandwidths_hz:
        if best.cost < EXACT_COST:
            break
        reg = _Regression(model, meas, t, h, problem.U, 2 * math.pi * fc)
        if reg.missing:
            return StartEstimate(reason="no measured channel of coordinate(s) "
                                        f"{', '.join(reg.missing)}: the equations of motion "
                                        "hold an unmeasured signal")
        if not np.any(reg.Q):
            return StartEstimate(reason="the record holds no motion")
        # equation weights: the known (mass) term of each equation at the start values
        wts = _equation_weights(reg, model, base)

        def solve_at(eta: FloatArray, fc: float = fc, reg: _Regression = reg,
                     wts: FloatArray = wts) -> tuple[dict[str, float], float, float]:
            p = dict(base)
            p.update({k: base[k] * float(f) for k, f in zip(nonlin, eta)})
            theta, rel, sv = _solve_linear(reg, model, p, lin, wts)
            p.update(zip(lin, (float(v) for v in theta)))
            # a negative spring or damper is no physical answer: such a point of the
            # length search ranks behind every physical one
            return p, rel + (1.0 if np.any(theta < 0) else 0.0), sv

        if nonlin:
            lifted = _lifted_seed(reg, model, base, lin, nonlin, wts)
            tries = seeds + ([last_u] if last_u is not None else [])
            if lifted is not None and np.all(np.abs(lifted) < 3.5):
                seeds = tries = [lifted]
            elif not seeds:  # the grid once, at the first bandwidth; later ones reuse it
                grid = list(itertools.product(NONLIN_GRID, repeat=len(nonlin))) \
                    if len(nonlin) <= 2 else [tuple([1.0] * len(nonlin))]
                scored = sorted((solve_at(np.array(g))[1], g) for g in grid)
                seeds = [np.log(np.array(g, dtype=float)) for _, g in scored[:3]]
            best_u, best_r = np.zeros(len(nonlin)), math.inf
            for g0 in tries if tries else seeds:
                res = nelder_mead(
                    lambda u: solve_at(np.exp(u))[1] if np.all(np.abs(u) < 3.5) else np.inf, g0,
                    initial_simplex=np.vstack([g0] + [g0 + 0.1 * e for e in np.eye(len(nonlin))]),
                    xatol=1e-5, fatol=1e-14, maxfev=60 * len(nonlin))
                if res.fun < best_r:
                    best_u, best_r = np.asarray(res.x, dtype=float), float(res.fun)
            last_u = best_u
            p, rel, sv = solve_at(np.exp(best_u))
        else:
            p, rel, sv = solve_at(np.zeros(0))
        if rel > REWEIGHT_REL:
            # start values decades off the record's (an absurd --init of a free mass) weigh
            # one equation so far above the others that the one holding the known scale is
            # ignored, and the estimate shrinks with them: weigh at the documented defaults
            # as well and keep the estimate that explains the record better
            alt = _equation_weights(reg, model, {**base, **{
                k: model.spec(k).default for k in free if model.spec(k).kind in ("mass", "inertia")}})
            if np.all(np.isfinite(alt)) and np.any(
                    np.abs(np.log(alt / wts)) > math.log(REWEIGHT_FACTOR)):
                eta = np.exp(last_u) if nonlin and last_u is not None else np.zeros(len(nonlin))
                p_alt, rel_alt, sv_alt = solve_at(eta, wts=alt)
                if (problem.normalized_ss({**base, **{k: float(p_alt[k]) for k in free}})
                        < problem.normalized_ss({**base, **{k: float(p[k]) for k in free}})):
                    p, rel, sv, wts = p_alt, rel_alt, sv_alt, alt
        if sv < RANK_TOL:
            reasons.append(f"{fc:.3g} Hz: too little excitation to separate "
                           f"{', '.join(lin)} (relative singular value {sv:.1e})")
            continue
        vals, floored, notes = _floored(model, base, lin, {k: float(p[k]) for k in free},
                                        "equation-error")
        cost = problem.normalized_ss({**base, **vals})
        if cost >= EXACT_COST and noisy and not poly:
            poly.append(_coef_poly(model, base, lin, nonlin))
        if cost >= EXACT_COST and noisy and poly[0] is not None:
            # not exact: noise in the record (or too little of the model in it); the
            # noise-compensated fit from this estimate and from the given start as well
            given = {k: base[k] for k in free}
            starts = [vals, given]
            if nonlin:
                starts += [{**vals, **{k: base[k] for k in nonlin}},
                           {**given, **{k: vals[k] for k in nonlin}}]
            # every run's end point is a candidate; the output-error cost chooses, as it
            # does among the bandwidths
            for comp in _ratio_fit(reg.with_noise(), poly[0][0], lin, nonlin, starts) or []:
                comp, comp_floored, comp_notes = _floored(model, base, lin, comp,
                                                          "noise-compensated")
                comp_cost = problem.normalized_ss({**base, **comp})
                if comp_cost < cost:
                    vals, cost, floored = comp, comp_cost, comp_floored
                    notes = ["compensated for the measurement noise (errors in variables)",
                             *comp_notes]
        if cost < best.cost:
            best = StartEstimate(values=vals, bandwidth_hz=fc, cost=float(cost), notes=notes,
                                 undetermined=floored)
            best_reg = (reg, wts)
            if noisy and not floored and noise_floor_ratio(problem, {**base, **vals}) <= NOISE_FLOOR:
                break  # leaves only white noise: no other bandwidth can do better
    if not best.values and reasons:
        best.reason = "; ".join(reasons)
    if best.values and best.cost >= EXACT_COST and best_reg is not None:
        best = _refine_iv(problem, best, best_reg[0], best_reg[1], base, lin, nonlin, h)
    return best


def _refine_iv(problem: OutputErrorProblem, est: StartEstimate, reg: "_Regression",
               wts: FloatArray, base: Mapping[str, float], lin: list[str], nonlin: list[str],
               h: float, iterations: int = 4) -> StartEstimate:
    """Instrumental-variable iterations against the bias that noise puts in the regressors.

    The instruments are the same filters applied to the model's noise-free simulated
    motion at the current estimate (refined instrumental variables); an iterate is kept
    only when it lowers the output-error cost.
    """
    model = problem.model
    nq = len(model.coords)
    for _ in range(iterations):
        p = {**base, **est.values}
        try:
            x0 = problem.predict(p).x0
            X = simulate_states(model, p, problem.t, problem.U, x0)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            break
        if not np.all(np.isfinite(X)):
            break
        sim = Measurement(t=problem.t, road=problem.meas.road,
                          measured={**{c: X[:, i] for i, c in enumerate(model.coords)},
                                    **{f"{c}_dot": X[:, nq + i] for i, c in enumerate(model.coords)}})
        iv = reg.with_instruments(_Regression(model, sim, problem.t, h, problem.U,
                                              2 * math.pi * est.bandwidth_hz,
                                              segments=reg.segments))
        q = dict(p)
        if nonlin:
            u = _lifted_seed(iv, model, p, lin, nonlin, wts)
            if u is not None and np.all(np.abs(u) < 3):
                q.update({k: p[k] * math.exp(v) for k, v in zip(nonlin, u)})
        theta, _, _ = _solve_linear(iv, model, q, lin, wts)
        if not np.all(theta > 0):
            break
        q.update(zip(lin, (float(v) for v in theta)))
        vals = {k: float(q[k]) for k in est.values}
        cost = problem.normalized_ss({**base, **vals})
        if not cost < est.cost:
            break
        est = StartEstimate(values=vals, bandwidth_hz=est.bandwidth_hz, cost=float(cost),
                            notes=est.notes + ["refined by instrumental variables"],
                            undetermined=est.undetermined)
    return est


def data_driven_start(model: SuspensionModel, data: Measurement, fixed: Mapping[str, float],
                      init: Mapping[str, float] | None = None, cost: str = "sse") -> dict[str, float]:
    """Starting values of every free parameter of ``model`` from the record ``data``.

    Parameters
    ----------
    model : SuspensionModel
    data : Measurement
        The record (measured channels, road).
    fixed : mapping
        Known parameters (SI); every other parameter is free.
    init : mapping, optional
        Centre of the search for parameters that do not enter the equations linearly
        (default: the model's documented defaults).
    cost : {"sse", "frobenius"}
        Cost used to rank the candidate estimates.

    Returns
    -------
    dict
        Free parameter -> estimate (SI); empty when the record does not allow one (see
        :func:`estimate_start` for the reasons).
    """
    free_init = {k: v for k, v in (init or {}).items() if k not in fixed}
    params = Parameters.for_model(model, fix=fixed, init=free_init)
    problem = OutputErrorProblem(model, data, cost=cost)
    return dict(estimate_start(problem, params).values)


#: normalised output-error cost of a data-driven estimate above which the given start is
#: run as well (the estimate explains less than half of the record) unless the fit from it
#: leaves only white noise
POOR_ESTIMATE = 0.5

#: normalised output-error cost below which a fit explains the record exactly (noise-free):
#: no other start can do better, so a further start is skipped. Any noisy record stays
#: above it, and there the estimate is biased (its regressors are the noisy channels
#: themselves: errors in variables) and may lead to a local minimum, so the given start runs
#: as well and the lower cost wins, unless the fit leaves only white noise (``NOISE_FLOOR``).
EXACT_FIT = 1e-10

#: :func:`noise_floor_ratio` up to which a fit to a noisy record counts as at the noise floor:
#: its residual is white noise, no other start can lower the cost by more than the noise's
#: own scatter, so a further start is skipped as for an exact fit. Fits at the floor measure
#: 0.97-1.04 on the seed's designs at 0.1-0.5 sigma; the local minima a biased estimate led
#: to measure 1.8-19.
NOISE_FLOOR = 1.15

#: :func:`noise_floor_ratio` of a fitted channel above which the fit of
#: :func:`fit_from_starts` is a misfit, not a success (:func:`misfit_channels`): the smooth,
#: non-white part of its residual at least equals the noise. Correct fits to ``suspid
#: simulate`` records (5 s at 200 Hz; quarter1, quarter2, half4, bump and ISO 8608 roads,
#: noise 0.1 and 0.5 of each channel's std) measure 0.99-1.06; every spring and damper (with
#: full7 the noise-free bump only) held at twice the truth 2.2-52 at 0.1-0.5 sigma (except
#: four at 0.5 sigma: 1.1-1.9, which the noise hides) and 777-1340 noise-free; the half
#: car's body mass at twice the truth (the rest free) 2.8-3.4 at 0.1 sigma (``python
#: tools/identify_misfit.py --can``).
MISFIT_FLOOR = 2.0
#: share of the record's signal (the fitted channels' sums of squares about their means,
#: weighted as in the cost) that a channel residual's excess over its noise floor must
#: exceed as well: a noise-free record has no noise floor (its ratio compares rounding
#: errors: 1.0-1.5, quantized as a CAN log too, but 553 on the full car's bump), and there
#: a correct fit leaves at
#: most 1e-20 (1.1e-8 quantized), while a quarter car's body mass held at twice the truth
#: with its springs and dampers free leaves 1.3e-5 (bump) and 6.7e-4 (ISO road), every
#: spring and damper at twice the truth 0.01-0.26 (same command).
MISFIT_SHARE = 1e-5

#: a free parameter this far (factor) from its start and from the data-driven estimate ran away
#: (unless a second start, begun far from the first in it, reached the same fit: :func:`_confirmed`)
RUNAWAY = 100.0
#: relative distance, or distance in standard errors, within which two fits are the same
#: point (:func:`_same`)
CONFIRM_TOL = 0.01
CONFIRM_SIGMA = 0.3
#: factor by which a confirmed parameter, moved alone up or down, must raise the cost by more
#: than 3 sigma of the noise (:func:`_confirmed`): the record bounds it within a decade on
#: at least one side
CONFIRM_SPAN = 10.0

#: factor beyond which two fits to a noisy record reached from different starts at costs the
#: noise does not tell apart (:func:`_within_noise`) are reported as undecided: neither a
#: success nor identifiable
AGREE = 10.0

#: factor within which the fit from the data-driven start must agree with the given start in
#: every free parameter for the noise-floor rule to skip the given start. The whiteness test
#: (:func:`noise_floor_ratio`) only sees a misfit larger than ``NOISE_FLOOR - 1`` of the
#: residual; at 0.3-0.5 sigma noise the noise dominates the residual, and a local minimum
#: whose misfit is a few per cent of it passes as white (half4 sse row 25: k4 at 2.3e6 N/m
#: from an estimate of 2.1e6 against a truth of 500, ratio below 1.15, cost 21.65 against
#: 20.63 from the given start). A fit far from the given start in some parameter is such a
#: case or a poor given start; only running the given start tells. The factor lies between
#: the given starts' own error in the studies (up to 10x: a correct fit from them is ~10x
#: away, and at 10 it ran every such start in full, 1.7-5x the time) and ``RUNAWAY``; the
#: local minimum above is 460-46000x from given starts 0.1x-10x.
SKIP_AGREE = 30.0


#: common factors tried per kind of free parameter (damping, stiffness, length, ...) on the
#: given start by :func:`kind_scaled_start`: 0.01 to 100 in decades (a Nelder-Mead from the
#: best point finishes; half decades, 5.8 times the costs for three kinds, found the same
#: basins on the designs' far starts and one more of six scattered starts)
KIND_GRID = 10.0 ** np.linspace(-2.0, 2.0, 5)
#: :func:`kind_scaled_start` searches at most this many kinds at once (``5**3`` costs)
KIND_MAX = 3
#: factor by which some kind's common factor must leave 1 for the rescaled given start to
#: be run as a further start (within it, it is the given start again)
KIND_MIN_FACTOR = 3.0

#: factor by which one of two twin fits (:func:`_choose_twin`) must fit the measured
#: channels outside the cost better (in squared residual per channel variance) for those
#: channels to choose between them
TWIN_DECIDE = 4.0


def kind_scaled_start(problem: OutputErrorProblem, params: Parameters
                      ) -> tuple[Parameters, dict[str, float], float] | None:
    """The given start with each kind of free parameter rescaled by one common factor.

    A start that is off by one factor per kind (every damper 10x, every length in the
    wrong unit, a nominal vehicle of another class) keeps the *ratios* within each kind
    right; one output-error cost per point of a coarse grid of factors (``KIND_GRID`` per
    kind, at most ``KIND_MAX`` kinds) and a short Nelder-Mead from the best point find the
    common factors, a search of 1-3 dimensions instead of one per parameter.

    Parameters
    ----------
    problem : OutputErrorProblem
        The record and cost.
    params : Parameters
        Fixed values and the given start of the free parameters.

    Returns
    -------
    tuple or None
        ``(start, factors, cost)``: the rescaled start, the factor of each kind
        (dimensionless) and its normalised cost; ``None`` when there are more than
        ``KIND_MAX`` kinds or no finite cost.
    """
    free = params.free
    model = problem.model
    kinds = sorted({model.spec(k).kind for k in free})
    if not free or len(kinds) > KIND_MAX:
        return None
    base = params.valuesdict()
    col = [kinds.index(model.spec(k).kind) for k in free]

    def scaled(u: FloatArray) -> dict[str, float]:
        out = dict(base)
        for k, j in zip(free, col):
            out[k] = min(max(base[k] * math.exp(float(u[j])), params[k].min), params[k].max)
        return out

    def cost(u: FloatArray) -> float:
        return problem.normalized_ss(scaled(u)) if np.all(np.abs(u) < 6.0) else math.inf

    logs = np.log(KIND_GRID)
    c0, u0 = min(((cost(g), g) for g in map(np.array, itertools.product(logs, repeat=len(kinds)))),
                 key=lambda cu: cu[0])
    if not math.isfinite(c0):
        return None
    step = 0.5 * float(logs[1] - logs[0])
    res = nelder_mead(cost, u0, initial_simplex=np.vstack([u0] + [u0 + step * e
                                                                  for e in np.eye(len(kinds))]),
                      xatol=1e-2, fatol=1e-6, maxfev=60 * len(kinds))
    u, c = (np.asarray(res.x, dtype=float), float(res.fun)) if res.fun <= c0 else (u0, c0)
    out = params.copy()
    for k, v in scaled(u).items():
        if k in free:
            out[k].value = float(v)
    return out, {kd: math.exp(float(u[i])) for i, kd in enumerate(kinds)}, c


def noise_floor_ratio(problem: OutputErrorProblem, p: Mapping[str, float]) -> float:
    """Weighted sum of squares of the residual over what white noise alone would give.

    The noise variance of every channel is estimated from the residual itself, from its
    sample-to-sample differences (``mean(diff(r)^2) / 2``): white measurement noise passes
    them unchanged, while a misfit (a local minimum, a biased estimate) is a response of the
    model, smooth at the sampling rate, and hardly enters them. The ratio is therefore about
    1 (within a few ``sqrt(2 / N)``) for a fit at the noise floor, and above it by the
    misfit's share of the residual otherwise. ``inf`` where it cannot be evaluated.
    """
    parts = noise_floor_parts(problem, p)
    if parts is None:
        return math.inf
    num = sum(a for a, _ in parts.values())
    den = sum(b for _, b in parts.values())
    if not (den > 0 and math.isfinite(num)):
        return math.inf
    return num / den


def noise_floor_ratios(problem: OutputErrorProblem, p: Mapping[str, float]) -> dict[str, float]:
    """:func:`noise_floor_ratio` of every fitted channel on its own (channel -> ratio).

    ``inf`` for a channel where it cannot be evaluated; empty when the prediction fails.
    """
    parts = noise_floor_parts(problem, p)
    return {} if parts is None else ratios_of_parts(parts)


def ratios_of_parts(parts: Mapping[str, tuple[float, float]]) -> dict[str, float]:
    """Channel -> ratio from :func:`noise_floor_parts` (``inf`` where it cannot be formed)."""
    return {c: (a / b if b > 0 and math.isfinite(a) else math.inf) for c, (a, b) in parts.items()}


def noise_floor_parts(problem: OutputErrorProblem, p: Mapping[str, float]
                      ) -> dict[str, tuple[float, float]] | None:
    """Per fitted channel: the residual's sum of squares and what white noise would give.

    The second is ``sum(diff(r)^2) / 2`` scaled to the residual's length (same units
    squared as the channel); channels with fewer than 3 finite residuals are left out.
    ``None`` when the prediction fails.
    """
    try:
        r = problem.predict(p).residual
    except (np.linalg.LinAlgError, ValueError, FloatingPointError):
        return None
    return residual_noise_floor_parts(r, problem.channels)


def residual_noise_floor_parts(r: FloatArray, channels: Sequence[str]
                               ) -> dict[str, tuple[float, float]]:
    """:func:`noise_floor_parts` of a given residual ``r`` (samples x channels, NaN where
    missing; ``channels`` names its columns)."""
    out: dict[str, tuple[float, float]] = {}
    for j, c in enumerate(channels):
        rj = r[:, j]
        rj = rj[np.isfinite(rj)]
        if rj.size < 3:
            continue
        d = np.diff(rj)
        out[c] = (float(rj @ rj), float(d @ d) / 2.0 * rj.size / d.size)
    return out


def misfit_measures(problem: OutputErrorProblem, p: Mapping[str, float]
                    ) -> dict[str, tuple[float, float]]:
    """Per fitted channel: its noise-floor ratio and the excess's share of the signal.

    The ratio is :func:`noise_floor_ratios`' (``inf`` with no noise floor at all); the
    share is the channel residual's sum of squares less its noise floor over the fitted
    channels' summed sums of squares about their means (weighted as in the cost;
    dimensionless; below 0 when the residual is all noise). A channel the record hardly
    moves (the roll of a symmetric bump) thus weighs what it weighs in the cost. Channels
    with fewer than 3 finite samples are left out; empty when the prediction fails or the
    record does not move.
    """
    parts = noise_floor_parts(problem, p)
    if parts is None:
        return {}
    var = 0.0
    for j in range(len(problem.channels)):
        y = problem.Ymeas[:, j]
        y = y[np.isfinite(y)]
        if y.size:
            var += float(np.sum((y - y.mean()) ** 2)) * float(problem.w[j]) ** 2
    if not var > 0:
        return {}
    out: dict[str, tuple[float, float]] = {}
    for j, c in enumerate(problem.channels):
        if c in parts and math.isfinite(parts[c][0]):
            a, b = parts[c]
            out[c] = (a / b if b > 0 else math.inf, (a - b) * float(problem.w[j]) ** 2 / var)
    return out


def misfit_channels(problem: OutputErrorProblem, p: Mapping[str, float]
                    ) -> dict[str, tuple[float, float]]:
    """Fitted channels whose residual at ``p`` is clearly more than measurement noise.

    A channel is a misfit when its noise-floor ratio exceeds ``MISFIT_FLOOR`` and the
    residual's excess over the noise floor exceeds ``MISFIT_SHARE`` of the record's signal
    (:func:`misfit_measures`). A fit at the noise floor (ratio about 1) or one that
    leaves a negligible part of the signal (a noise-free or quantized record fitted well) is
    none.

    Parameters
    ----------
    problem : OutputErrorProblem
        The record and cost.
    p : mapping
        Every parameter's value (SI).

    Returns
    -------
    dict
        Channel -> ``(ratio, share)`` of the misfit channels (both dimensionless); empty
        when there is no misfit or the prediction fails.
    """
    return {c: (r, sh) for c, (r, sh) in misfit_measures(problem, p).items()
            if r > MISFIT_FLOOR and sh > MISFIT_SHARE}


def misfit_warning(misfit: Mapping[str, tuple[float, float]], fixed: Mapping[str, float]
                   ) -> str:
    """The one-line warning of a misfit (:func:`misfit_channels`), naming the held values."""
    chans = ", ".join(f"{c} (noise-floor ratio {r:.3g}, {100.0 * sh:.3g} % of the signal)"
                      for c, (r, sh) in misfit.items())
    held = ", ".join(f"{k}={v:.6g}" for k, v in fixed.items())
    cause = (f"likely causes: a value held fixed ({held}: --fix), an effect the model lacks "
             "(suspid diagnose) or a faulty channel" if held
             else "likely causes: a local minimum, an effect the model lacks (suspid diagnose) "
                  "or a faulty channel")
    return (f"misfit: the fit leaves far more than measurement noise on {chans}; the model "
            f"does not explain the record; {cause}")


def _exact(problem: OutputErrorProblem, res: IdentResult) -> bool:
    """``res`` explains the record exactly (a noise-free record)."""
    return bool(problem.normalized_ss(res.params) < EXACT_FIT)


def _at_noise_floor(problem: OutputErrorProblem, res: IdentResult) -> bool:
    """``res`` leaves only white measurement noise on a noisy record (not an exact fit)."""
    return not _exact(problem, res) and noise_floor_ratio(problem, res.params) <= NOISE_FLOOR


def _far(a: Mapping[str, float], b: Mapping[str, float], free: list[str],
         factor: float) -> list[str]:
    """Free parameters in which ``a`` and ``b`` differ by more than ``factor`` (or are not
    both finite and positive)."""
    out = []
    for k in free:
        x, y = float(a[k]), float(b[k])
        if not (math.isfinite(x) and math.isfinite(y) and x > 0 and y > 0) \
                or abs(math.log(x / y)) > math.log(factor):
            out.append(k)
    return out


def _within_noise(problem: OutputErrorProblem, best: IdentResult, other: IdentResult,
                  nfree: int) -> bool:
    """``other``'s cost exceeds ``best``'s by less than 3 sigma of the noise (noisy records).

    The noise-scaled expectation is the band's own level: a cost rise of ``SIGMAS**2`` times
    the residual variance per sample, ``ss / (N - p)`` (normalised units), is what a 3-sigma
    step of one parameter costs; two fits closer than that are not told apart by the record.
    """
    if _exact(problem, best):
        return False
    ss_best = problem.normalized_ss(best.params)
    ss_other = problem.normalized_ss(other.params)
    try:
        n = int(problem.residual_vector(best.params).size)
    except (np.linalg.LinAlgError, ValueError, FloatingPointError):
        return False
    if not (math.isfinite(ss_best) and math.isfinite(ss_other)) or n <= nfree:
        return False
    return ss_other - ss_best <= SIGMAS ** 2 * ss_best / (n - nfree)


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _plausibility(res: IdentResult, free: list[str], start: Mapping[str, float],
                  data: Mapping[str, float]) -> list[tuple[str, str]]:
    """Free parameters at which ``res`` sits at an absurd place, each with the reason (empty
    when there is none)."""
    out = []
    for k in free:
        v = res.params[k]
        if not (math.isfinite(v) and v > 0):
            out.append((k, f"{k} reached {v!r}, not a finite positive value"))
            continue
        far_start = k not in start or abs(math.log(v / start[k])) > math.log(RUNAWAY)
        far_data = k not in data or abs(math.log(v / data[k])) > math.log(RUNAWAY)
        if far_start and far_data:
            ref = f" and from the data-driven estimate {data[k]:.4g}" if k in data else ""
            if k not in start and k not in data:
                continue  # neither a given start nor a usable estimate to compare with
            st = f"its start {start[k]:.4g}" if k in start else "its start"
            out.append((k, f"{k} ran to {v:.4g}, more than {RUNAWAY:g}x from {st}{ref}; "
                           "the record does not support it"))
    return out


def _same(a: IdentResult, b: IdentResult, k: str) -> bool:
    """``b``'s value of ``k`` is ``a``'s: within ``CONFIRM_TOL`` (relative) or within
    ``CONFIRM_SIGMA`` standard errors of ``a`` (a weakly determined parameter ends where
    each search stops on a nearly flat cost)."""
    x, y = float(a.params[k]), float(b.params[k])
    if not (math.isfinite(x) and math.isfinite(y) and x > 0 and y > 0):
        return False
    se = a.stderr.get(k)
    tol = max(CONFIRM_TOL, CONFIRM_SIGMA * se / x if se is not None and math.isfinite(se) else 0.0)
    return abs(y / x - 1.0) <= tol


def _confirmed(problem: OutputErrorProblem, res: IdentResult, start: Mapping[str, float],
               k: str, free: list[str],
               others: Sequence[tuple[str, Mapping[str, float], IdentResult]]) -> str | None:
    """Label of another start that confirms ``res``'s value of ``k`` (``None`` if none does).

    A parameter that ran far from its start along a flat direction of the cost, or into a
    local minimum, is not confirmed. Two conditions together say the record itself puts it
    there: a second start, begun more than ``KIND_MIN_FACTOR`` x away from this one in
    ``k``, reached the same fit (every free parameter the same: :func:`_same`), and
    the record bounds ``k`` on at least one side (moving ``k`` alone a factor
    ``CONFIRM_SPAN`` up and down lowers the cost neither way by more than 3 sigma of the
    noise and raises it one way by more than that; a drift along a flat direction to zero or
    infinity leaves it unchanged both ways). The profile bands then say
    how well the record bounds it, and name a side it leaves open.
    """
    v = res.params[k]
    if not (math.isfinite(v) and v > 0):
        return None
    label = None
    for lab, s, r in others:
        if r is res or k not in s or k not in start \
                or abs(math.log(s[k] / start[k])) <= math.log(KIND_MIN_FACTOR):
            continue
        if all(_same(res, r, j) for j in free):
            label = lab
            break
    if label is None:
        return None
    ss = problem.normalized_ss(res.params)
    try:
        n = int(problem.residual_vector(res.params).size)
    except (np.linalg.LinAlgError, ValueError, FloatingPointError):
        return None
    if not math.isfinite(ss) or n <= len(free):
        return None
    rise = max(SIGMAS ** 2 * ss / (n - len(free)), EXACT_FIT)
    bounded = False
    for f in (CONFIRM_SPAN, 1.0 / CONFIRM_SPAN):
        moved = dict(res.params)
        moved[k] = v * f
        c = problem.normalized_ss(moved)
        if math.isfinite(c) and c < ss - rise:
            return None  # not even a minimum along k
        bounded = bounded or (math.isfinite(c) and c - ss > rise)
    return label if bounded else None


def _reject(res: IdentResult, warnings: list[str]) -> None:
    """Report ``res`` as neither a success nor identifiable, with the reasons."""
    res.success = False
    res.identifiable = False
    for entry in res.starts or []:
        if entry.get("chosen"):
            entry["success"] = False
    res.warnings += warnings


# a parameter set far from any physical value overflows the response: such a cost is
# infinite (the search moves on), not a RuntimeWarning with its source line on stderr
@np.errstate(over="ignore", invalid="ignore", divide="ignore")
def fit_from_starts(problem: OutputErrorProblem, params: Parameters,
                    run: Callable[[Parameters], IdentResult], *, data_start: bool = True,
                    keep_init: bool = True, init_fallback: bool = True,
                    intervals: bool = True, estimate: StartEstimate | None = None) -> IdentResult:
    """Run the fit ``run`` from the data-driven start and from ``params``; keep the best.

    Parameters
    ----------
    problem : OutputErrorProblem
        The whole record (for the data-driven estimate).
    params : Parameters
        Fixed values and the given start of the free parameters.
    run : callable
        ``run(start) -> IdentResult``: one identification from the start ``start``.
    data_start : bool
        Compute the data-driven start (:func:`estimate_start`) and run from it.
    keep_init : bool
        Also consider ``params`` as a start (always done when no data-driven start exists).
        It is skipped (listed as skipped, so the time per identification does not grow)
        when the fit from the data-driven start is a clean success (converged, identifiable,
        plausible), ``params`` begins at no lower cost than the estimate (else it may lie in
        a better basin), and the fit either leaves only white measurement noise (a noisy
        record: :func:`noise_floor_ratio` at most ``NOISE_FLOOR``; no start can then lower
        the cost by more than the noise's own scatter) while agreeing with ``params`` within
        a factor ``SKIP_AGREE`` in every free parameter (the whiteness test cannot see a
        misfit that is a few per cent of a noise-dominated residual, so a fit far from the
        given start is checked against it) or explains the record exactly (normalised cost
        below ``EXACT_FIT``) from an estimate that fits well (normalised cost below
        ``POOR_ESTIMATE``). Otherwise it runs: on a noisy record the estimate is biased and
        may lead to a local minimum, whose residual is not white.
    init_fallback : bool
        With ``keep_init`` false (no start given: ``params`` holds the documented defaults),
        still run ``params`` when the fit from the data-driven start gives no clean answer
        (below). A noisy record can mislead the estimate badly (e.g. positions alone at 0.3
        sigma), and the defaults, a typical car, are then the better guess.
    intervals : bool
        Attach honest 3-sigma bands (:func:`estimator.identify.profile.apply_bands`) to a
        result with standard errors: the curvature band where the cost is quadratic out to
        its ends, the profile likelihood where it is not; a parameter the profile does not
        bound makes the result not identifiable.
    estimate : StartEstimate, optional
        The data-driven start of ``problem`` when already computed
        (:func:`estimate_start`); default: computed here when ``data_start``.

    Returns
    -------
    IdentResult
        The lowest-cost result, with ``starts`` (every start and what it reached),
        ``data_start`` and ``nfev`` summed over the runs. A result whose parameters ran
        orders of magnitude away from its start and from the data-driven estimate is
        reported neither as a success nor as identifiable; its warnings say which parameter
        and why, and the costs reached from each start. So is a noisy result when another
        start reached a fit more than ``AGREE`` x away in some parameter at a cost within
        3 sigma of the noise of it (the record does not decide between the two): the
        warning names the parameters, the starts and their costs. So is a noisy result from
        the data-driven start when the given start ran and its fit failed while the result
        lies more than ``SKIP_AGREE`` x from the given start, or the estimate began at a
        higher cost than the given start (no second start confirms it; the warning begins
        ``unconfirmed result``).

        When no start gives a clean answer (the result would be rejected, is no success,
        or leaves a residual that is not white: :func:`noise_floor_ratio` above
        ``NOISE_FLOOR`` and no exact fit) and the given start was considered, the given start rescaled by one
        common factor per kind of parameter (:func:`kind_scaled_start`) is a third start
        (``"scaled"`` in ``starts``) if it begins at a lower cost than every start so far
        and some factor lies outside ``[1/KIND_MIN_FACTOR, KIND_MIN_FACTOR]``; the rules
        above are then applied to all three (a fit from it is checked against the given
        start as a fit from the estimate is). A clean answer from the first two starts
        costs nothing more.
    """
    free = params.free
    est = (estimate if estimate is not None
           else estimate_start(problem, params) if data_start and free else None)
    runs: list[tuple[str, Parameters]] = []
    if est is not None and est.values:
        p = params.copy()
        for k, v in est.values.items():
            p[k].value = float(v)
        runs.append(("data", p))
    if keep_init or not runs:
        runs.append(("init", params))
    at_start = [problem.normalized_ss(s.valuesdict()) for _, s in runs]
    data_vals = ({k: v for k, v in est.values.items() if k not in est.undetermined}
                 if est is not None else {})

    def usable(label: str, start: Parameters) -> dict[str, float]:
        """Start values to judge a run-away against (not the floor of an unusable estimate)."""
        return {k: start[k].value for k in free if label != "data" or k in data_vals}

    results: list[tuple[str, Parameters, IdentResult | None]] = []
    for i, (label, start) in enumerate(runs):
        done = [r for _, _, r in results if r is not None]
        # a further start only runs when the fits so far are not clean, or when it begins
        # lower than the start they came from (it may then be in a better basin)
        # (or when the fits so far explain the record down to its noise: no start can
        # then lower the cost by more than the noise's own scatter)
        if done and all(r.success for r in done) and at_start[i] >= min(at_start[:i]) \
                and (est is not None
                     and est.cost < POOR_ESTIMATE and all(_exact(problem, r) for r in done)
                     or all(_at_noise_floor(problem, r) for r in done)
                     and not any(_far(r.params, start.valuesdict(), free, SKIP_AGREE)
                                 for r in done)) \
                and not _plausibility(done[0], free, usable(runs[0][0], runs[0][1]), data_vals):
            results.append((label, start, None))
            continue
        results.append((label, start, run(start)))
    issues = _issues(problem, results, at_start, free, data_vals, usable)

    def unclean(issues: _Issues) -> bool:
        """No clean answer: rejected, no success, or a residual that is not white noise."""
        return issues.rejected or not issues.res.success or not _exact(problem, issues.res) \
            and noise_floor_ratio(problem, issues.res.params) > NOISE_FLOOR

    if init_fallback and not any(label == "init" for label, _ in runs) and unclean(issues):
        # no start was given and the record's estimate gave no clean answer: the defaults
        runs.append(("init", params))
        at_start.append(problem.normalized_ss(params.valuesdict()))
        results.append(("init", params, run(params)))
        issues = _issues(problem, results, at_start, free, data_vals, usable)
    if unclean(issues):
        # no clean answer (or a residual that is not white noise: a local minimum): the
        # given start rescaled kind by kind is a further start when it begins lower than
        # every start run and is not the given start again
        scaled = (kind_scaled_start(problem, params)
                  if any(label == "init" for label, _ in runs) else None)
        if scaled is not None and scaled[2] < min(at_start) and any(
                abs(math.log(f)) > math.log(KIND_MIN_FACTOR) for f in scaled[1].values()):
            runs.append(("scaled", scaled[0]))
            at_start.append(scaled[2])
            results.append(("scaled", scaled[0], run(scaled[0])))
            issues = _issues(problem, results, at_start, free, data_vals, usable)
    if issues.runaway and not issues.ambiguous and not issues.unconfirmed and all(
            math.isfinite(issues.res.params[k]) and issues.res.params[k] > 0
            for k in issues.runaway):
        # parameters that ran far from their start and no other start reached: a further
        # start next to the fit, those parameters moved CONFIRM_SPAN x back towards where
        # they came from, returns to it if the cost has a minimum there (a drift along a
        # flat direction stays where it is put)
        ref = usable(*issues.best[:2])
        c = params.copy()
        for k in free:
            v = float(issues.res.params[k])
            c[k].value = v if k not in issues.runaway else \
                v * (CONFIRM_SPAN if ref.get(k, v) > v else 1.0 / CONFIRM_SPAN)
        runs.append(("confirm", c))
        at_start.append(problem.normalized_ss(c.valuesdict()))
        results.append(("confirm", c, run(c)))
        issues = _issues(problem, results, at_start, free, data_vals, usable)
    res = issues.res
    twin_warning = None
    if not (issues.bad or issues.ambiguous or issues.unconfirmed):
        res, twin_run, twin_warning = resolve_twin(problem, params, res, run)
        if twin_run is not None:
            runs.append(("twin", twin_run[0]))
            at_start.append(problem.normalized_ss(twin_run[0].valuesdict()))
            results.append(("twin", *twin_run))
    ran = [(label, s, r) for label, s, r in results if r is not None]
    res.nfev = int(sum(r.nfev for _, _, r in ran))
    res.starts = []
    for (label, s, r), c0 in zip(results, at_start):
        entry: dict[str, Any] = {"start": label, "from": {k: float(s[k].value) for k in free},
                                 "cost_at_start": _finite(problem.seed_cost(c0 * problem.scale))}
        if r is None:
            entry.update({"cost": None,
                          "skipped": "the fit from the data-driven start is clean and "
                                     "explains the record down to white noise within "
                                     f"{SKIP_AGREE:g}x of this start, or exactly from a good "
                                     "estimate while this start begins at no lower cost"})
        else:
            entry.update({"cost": _finite(r.cost), "params": {k: float(r.params[k]) for k in free},
                          "success": bool(r.success), "chosen": r is res})
        res.starts.append(entry)
    if est is not None:
        res.data_start = ({"values": dict(est.values), "bandwidth_hz": est.bandwidth_hz,
                           "notes": list(est.notes)} if est.values
                          else {"reason": est.reason})
        if not est.values:
            res.warnings.append(f"no data-driven start: {est.reason}")
    if issues.bad:
        # a parameter that ran orders of magnitude away along a flat direction of the cost
        # is not identified by this record, whatever the curvature at the end point says
        alts = ", ".join(f"{label} start: cost {r.cost:.4g}" for label, _, r in ran)
        _reject(res, [f"implausible result: {b}" for b in issues.bad]
                + [f"costs reached from each start: {alts}"])
    elif issues.ambiguous:
        # two starts reached places an order of magnitude apart at costs the noise does not
        # tell apart: the record does not decide between them, whatever each curvature says
        _reject(res, issues.ambiguous)
    elif issues.unconfirmed:
        _reject(res, issues.unconfirmed)
    elif intervals:
        apply_bands(problem, res, free)
    if twin_warning is not None:
        res.warnings.append(twin_warning)
    misfit = misfit_channels(problem, res.params)
    if misfit:
        # the model does not explain the record, however well the optimiser converged
        res.success = False
        for entry in res.starts:
            if entry.get("chosen"):
                entry["success"] = False
        res.warnings.append(misfit_warning(misfit, {k: res.params[k] for k in params.fixed}))
    return res


def twin_of(problem: OutputErrorProblem, params: Parameters, p: Mapping[str, float]
            ) -> Twin | None:
    """The model's twin of ``p`` on the coordinates in ``problem``'s cost, or ``None``.

    :meth:`SuspensionModel.twin`, for the coordinates with a channel in the cost. ``None``
    as well when some free value of ``p`` is not finite and positive, or the twin would
    change a parameter ``params`` holds fixed (the record is then not ambiguous: the twin
    lies outside what is identified).
    """
    model = problem.model
    measured = problem.measured_coords()
    if not all(math.isfinite(p[k]) and p[k] > 0 for k in params.free):
        return None
    tw = model.twin(p, measured)
    if tw is None or any(not math.isclose(tw.params[k], p[k], rel_tol=1e-12)
                         for k in params.fixed):
        return None
    return tw


def resolve_twin(problem: OutputErrorProblem, params: Parameters, res: IdentResult,
                 run: Callable[[Parameters], IdentResult]
                 ) -> tuple[IdentResult, tuple[Parameters, IdentResult] | None, str | None]:
    """``res`` or the fit ``run`` reaches from its twin (:func:`twin_of`), whichever is right.

    Returns the chosen result, ``(start, result)`` of the fit from the twin (``None`` when
    there is no twin: then ``res`` itself and no warning), and the warning that names the
    other fit when the two are equally good (:func:`_choose_twin`).
    """
    tw = twin_of(problem, params, res.params)
    if tw is None:
        return res, None, None
    start = params.copy()
    for k in params.free:
        start[k].value = float(tw.params[k])
    other = run(start)
    best, warning = _choose_twin(problem, res, other, tw)
    return best, (start, other), warning


def _choose_twin(problem: OutputErrorProblem, res: IdentResult, other: IdentResult,
                 tw: Twin) -> tuple[IdentResult, str | None]:
    """Choose between ``res`` and ``other``, the fit from the model's twin of ``res``.

    A twin is a second parameter set with the same response on the channels in the cost
    (the quarter car's suspension and tyre seen from the body alone), so both fits reach
    the same cost and no optimiser can tell which is right. When they do (both exact, or
    within the noise: :func:`_within_noise`), measured channels outside the cost decide if
    one fits them ``TWIN_DECIDE`` times better (squared residual over the channel's
    variance, summed); otherwise the twin's physical rule decides (:attr:`Twin.rule`). A
    fit from the twin that ends at a clearly lower cost simply wins (``res`` was a local
    minimum). Returns the chosen result and a warning naming the other (``None`` when the
    costs decided).
    """
    same = (_exact(problem, res) and _exact(problem, other)
            or _within_noise(problem, res, other, len(res.stderr)))
    if not same:
        return (other if other.cost < res.cost else res), None
    outside = [c for c in res.rms_residual
               if c not in problem.channels and c in other.rms_residual]

    def misfit(r: IdentResult) -> float:
        total = 0.0
        for c in outside:
            var = float(np.nanvar(problem.meas.measured[c]))
            total += r.rms_residual[c] ** 2 / var if var > 0 else 0.0
        return total

    a, b = misfit(res), misfit(other)
    if outside and max(a, b) > TWIN_DECIDE * min(a, b) and max(a, b) > EXACT_FIT:
        take_other = b < a
        why = f"as the channels outside the cost ({', '.join(outside)}) fit it better"
    else:
        take_other = tw.prefer
        why = f"by the rule: {tw.rule}"
    best, alt = (other, res) if take_other else (res, other)
    vals = ", ".join(f"{k} = {alt.params[k]:.6g}" for k in alt.stderr)
    return best, (f"two fits explain the record equally well (costs {res.cost:.6g} and "
                  f"{other.cost:.6g}): the cost cannot tell {tw.swapped}; the other fit is "
                  f"{vals}; this one is chosen {why}")


@dataclass
class _Issues:
    """The lowest-cost fit of :func:`fit_from_starts` and why it is no success (if so)."""

    best: tuple[str, Parameters, IdentResult]
    bad: list[str]
    ambiguous: list[str]
    unconfirmed: list[str]
    #: the free parameters behind ``bad`` (ran away, not confirmed by another start)
    runaway: list[str]

    @property
    def res(self) -> IdentResult:
        return self.best[2]

    @property
    def rejected(self) -> bool:
        return bool(self.bad or self.ambiguous or self.unconfirmed)


def _issues(problem: OutputErrorProblem,
            results: list[tuple[str, Parameters, IdentResult | None]], at_start: list[float],
            free: list[str], data_vals: Mapping[str, float],
            usable: Callable[[str, Parameters], dict[str, float]]) -> _Issues:
    """The lowest-cost fit of ``results`` and the reasons to reject it (nothing changed)."""
    ran = [(label, s, r) for label, s, r in results if r is not None]

    def key(item: tuple[str, Parameters, IdentResult]) -> float:
        c = item[2].cost
        return c if math.isfinite(c) else math.inf

    # a confirmation run only vouches for (or against) the fit it started next to
    best = min((item for item in ran if item[0] != "confirm"), key=key)
    res = best[2]
    start = usable(best[0], best[1])
    others = [(label, usable(label, s), r) for label, s, r in ran]
    flagged = [(k, why) for k, why in _plausibility(res, free, start, data_vals)
               if _confirmed(problem, res, start, k, free, others) is None]
    bad = [why for _, why in flagged]
    ambiguous: list[str] = []
    for label, _, r in ran:
        far = _far(res.params, r.params, free, AGREE) if r is not res else []
        if far and _within_noise(problem, res, r, len(free)):
            ks = ", ".join(f"{k} {res.params[k]:.4g} ({best[0]} start) against "
                           f"{r.params[k]:.4g} ({label} start)" for k in far)
            ambiguous.append(
                f"implausible result: the {best[0]} and {label} starts reached fits more than "
                f"{AGREE:g}x apart ({ks}) at costs {res.cost:.4g} and {r.cost:.4g}, within "
                f"{SIGMAS:g} sigma of the noise; the record does not decide between them")
    # a noisy fit from the record's estimate (or from the rescaled given start) that the
    # given start was run to check, while the given start's own fit failed: no second start
    # confirms it when it lies more than SKIP_AGREE x from the given start, or (whatever the
    # distance) when its start began at a higher cost than the given start (it then does
    # not vouch for its basin)
    unconfirmed: list[str] = []
    if best[0] in ("data", "scaled") and not _exact(problem, res):
        c_best = at_start[[label for label, _, _ in results].index(best[0])]
        what, origin, led = {
            "data": ("the data-driven start", "an estimate", "the record's estimate"),
            "scaled": ("the rescaled init start", "a rescaled start", "the rescaling"),
        }[best[0]]
        for (label, s, got), c0 in zip(results, at_start):
            if label != "init" or got is None or got.success:
                continue
            far = _far(res.params, s.valuesdict(), free, SKIP_AGREE)
            if far:
                ks = ", ".join(f"{k} {res.params[k]:.4g} against {s[k].value:.4g}" for k in far)
                why = f"lies more than {SKIP_AGREE:g}x from the {label} start ({ks})"
            elif c_best > c0:
                why = (f"comes from {origin} that began at a higher cost than the {label} "
                       f"start ({problem.seed_cost(c_best * problem.scale):.4g} against "
                       f"{problem.seed_cost(c0 * problem.scale):.4g})")
            else:
                continue
            unconfirmed.append(
                f"unconfirmed result: the fit from {what} {why} on a noisy "
                f"record, and the fit from the {label} start failed (cost {got.cost:.4g} "
                f"against {res.cost:.4g}); no second start reached it, so {led} may have "
                "led to a local minimum")
    return _Issues(best, bad, ambiguous, unconfirmed, [k for k, _ in flagged])


def cold_start(model: SuspensionModel, meas: Measurement, params: Parameters,
               cost: str = "sse") -> Parameters:
    """``params`` with its free values replaced by the data-driven start when that fits better.

    For a fit with no earlier estimate to start from (a monitor's first window): the
    data-driven estimate is used when its output-error cost on ``meas`` is lower than the
    given (nominal) start's, so a far-off ``--nominal``/``--init`` does not decide the
    basin. Returns ``params`` itself when there is no usable estimate or it fits worse.
    """
    if not params.free:
        return params
    try:
        problem = OutputErrorProblem(model, meas, cost=cost)
    except (UsageError, ValueError, np.linalg.LinAlgError):
        return params
    est = estimate_start(problem, params)
    vals = {k: v for k, v in est.values.items() if k not in est.undetermined}
    if not vals:
        return params
    out = params.copy()
    for k, v in vals.items():
        out[k].value = float(v)
    if problem.normalized_ss(out.valuesdict()) < problem.normalized_ss(params.valuesdict()):
        return out
    return params
