"""A window's output-error problem with a lean per-evaluation path.

:class:`WindowProblem` is :class:`~estimator.identify.OutputErrorProblem` -- same cost, same
residuals, same variable projection of the initial state -- specialised for what a monitor
window almost always is: a uniform time grid, no missing sample in the fitted channels,
unit weights and ``x0="estimate"``. A warm window is fitted with ~10 Nelder-Mead
evaluations on ~750 samples, so the fixed cost of an evaluation (dozens of numpy calls on
2x2..4x4 arrays, 1-4 us each) matters as much as its O(N) part. For a parameter vector
``p`` the lean path computes:

1. ``A, B`` -- when the model's affine pieces are exact (the mass matrix fixed:
   :meth:`SuspensionModel.affine`, laid out once per monitor by :class:`StateSpaceMap`), as
   ``A0 + sum_k theta_k A_k``; otherwise by :meth:`SuspensionModel.state_space`;
2. the modal form ``A = V diag(lam) V^-1`` from one LAPACK ``dgeev`` (eigenvalues, right
   and left eigenvectors; the rows of ``V^-1`` are the left eigenvectors scaled by
   ``1 / (u^H v)``), with the acceptance test of :func:`suspid.simulate.modal_form`
   (condition number of ``V`` below 1e8);
3. the forced modal trajectory of the first-order-hold road,
   ``w[k+1] = E w[k] + g0 s[k] + g1 s[k+1]``, in closed form:
   ``w[k] = E^k (w[0] + sum_{l<k} d[l] E^-(l+1))`` -- one ``cumsum`` per mode of
   ``(sum_j a_j r_j[l]) E^-l`` (the roads summed first: the trajectory is linear in them)
   instead of a recursion. Exact in exact arithmetic; the partial sums are dominated by
   their newest terms, so the rounding error stays ~``eps`` relative to ``|w|``. It is used
   only while ``|E|^-N`` stays far from overflow (``max(-Re(lam)) h N < 600``);
4. the least-squares initial state without forming the free-response regressors
   ``Re(CV_i E_i^k)``, ``-Im(...)``: their Gram matrix from the channel products
   ``CV^T CV``, ``CV^T conj(CV)`` and the geometric sums ``sum_k (E_i E_j)^k``, their
   product with the residual as ``sum_c CV_ci (R P^T)_ci``; then the cost as
   ``||R0||^2 - rhs . sol`` (``R0`` the residual of the forced response, ``Gram sol = rhs``)
   without a residual pass, unless the two terms cancel (below :data:`SS_GUARD` of
   ``||R0||^2``: a noise-free window near its optimum), when the residual is formed and
   summed. The residual itself is formed when first asked for (prediction, residual
   vector, the stderr's secant), once per evaluation.
   ``python tools/bench_monitor.py evaluations`` times an evaluation of each model's
   751-sample window on this path and on the core's.

Evaluations are cached per window, so the estimate's residual and Nelder-Mead's final
simplex are reused by :meth:`WindowProblem.finish` (stderr from the secant through the
final simplex: no further evaluation). Every case the lean path does not cover (missing
samples, non-uniform grid, weights, a fixed ``x0``, a (nearly) defective ``A``, the
overflow guard, a Gram matrix with condition number > 1e12) goes to the parent class, so
results never depend on the path beyond rounding (~1e-12 relative in the cost;
``tests/stream/test_windowproblem.py`` checks it).

:meth:`WindowProblem.drift_residual` is the window with some parameters drifting linearly in
time (``WindowConfig.drift``): ``A`` and ``Bz`` per chunk of the window, one batched matrix
exponential for every chunk's first-order-hold discretisation, the initial state again by
least squares; with zero rates it equals the lean evaluation to rounding.
"""
from __future__ import annotations

import cmath
import math
from dataclasses import dataclass, field
from typing import ClassVar, Mapping

import numpy as np
from scipy.linalg import expm as _expm
from scipy.linalg.lapack import dgeev as _dgeev
from scipy.linalg.lapack import dgeqrf as _dgeqrf
from scipy.linalg.lapack import dgesv as _dgesv
from scipy.linalg.lapack import dsyev as _dsyev

from estimator.identify import OutputErrorProblem, Parameters, finish
from estimator.identify.identifiability import WEAK_TOL, Identifiability, assess
from estimator.identify.problem import Prediction, channel_kinds, output_maps
from estimator.identify.result import IdentResult
from suspid.models.base import FloatArray, SuspensionModel
from suspid.simulate import outputs, simulate_states

#: largest ``max(-Re(lam)) h N`` for which ``E**-N`` is formed (e^600 ~ 1e260 < 1.8e308)
MAX_DECAY_EXPONENT = 600.0
#: Gram-matrix condition number above which the parent's path is used (as the parent does)
MAX_GRAM_COND = 1e12
#: condition number of ``V`` above which ``A`` counts as defective (as modal_form)
MAX_V_COND = 1e8
#: the cost is taken as ``||R0||^2 - rhs . sol`` (the pre-fit residual's norm less what the
#: fitted free response removes, no residual pass) unless that is below this fraction of
#: ``||R0||^2``: then the two terms cancel and the residual is formed explicitly (a noise-free
#: window at its optimum). Above it the cancellation costs at most ~1e-16 / SS_GUARD of
#: relative precision; measured against the explicit sum on 751-sample windows of every
#: model at points up to 5 % from the truth: at most 4e-13 relative, the cost being
#: 10-90 % of ``||R0||^2`` there (the guard is for noise-free data)
SS_GUARD = 1e-4
#: lean evaluations kept per window (Nelder-Mead's final simplex is among the latest)
CACHE_SIZE = 32
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
_PATTERNS: dict[tuple[int, ...], "_Pattern"] = {}


def foh_weights(lm: complex, h: float) -> tuple[complex, complex, complex]:
    """Exact first-order-hold weights of one mode over one sample interval.

    For ``w' = lm w + b(t)`` with ``b`` linear between samples ``b0``, ``b1``:
    ``w1 = e w0 + g0 b0 + g1 b1``.

    Parameters
    ----------
    lm : complex
        Eigenvalue (1/s).
    h : float
        Sample interval (s).

    Returns
    -------
    e, g0, g1 : complex
        ``exp(lm h)`` and the weights (s) of the interval's first and last input sample
        (a series for ``|lm h| < 1e-3``, where the closed form cancels).
    """
    z = lm * h
    e = cmath.exp(z)
    if abs(z) < 1e-3:
        i0 = h * (1 + z / 2 + z * z / 6 + z ** 3 / 24)
        i1 = h * (0.5 + z / 6 + z * z / 24 + z ** 3 / 120)
    else:
        i0 = (e - 1) / z * h
        i1 = (e - 1 - z) / (z * z) * h
    return e, i0 - i1, i1


def foh_weights_modes(lam: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`foh_weights` of every mode at once.

    Parameters
    ----------
    lam : ndarray of complex
        Eigenvalues (1/s), shape (m,).
    h : float
        Sample interval (s).

    Returns
    -------
    e, g0, g1 : ndarray of complex
        Each (m,), as :func:`foh_weights` returns them per mode (the closed form in array
        arithmetic; the per-mode series when some ``|lm h| < 1e-3``).
    """
    z = lam * h
    if float(np.abs(z).min()) < 1e-3:
        e, g0, g1 = np.array([foh_weights(lm, h) for lm in lam.tolist()]).T
        return e, g0, g1
    e = np.exp(z)
    em1 = e - 1.0
    i1 = (em1 - z) / (z * z) * h
    return e, em1 / z * h - i1, i1


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


class StateSpaceMap:
    """``p -> (A, B, Bz)`` of a model, affine in the free parameters when that is exact.

    ``Bz = A B_v + B_r`` is the input matrix of the road in the simulator's
    ``z = x - B_v r`` coordinates (:mod:`suspid.simulate`). ``A`` and ``B`` come from the
    model's own affine pieces (:meth:`SuspensionModel.affine`, ``AB0 + sum_k theta_k dAB_k``
    laid out as the state-space blocks) when those are exact (the mass matrix fixed:
    ``AffinePieces.exact``); ``Bz`` is affine too when ``B_v`` (tyre damping over wheel
    mass) does not depend on the free parameters (``dAB`` zero in the road-rate columns).
    When the pieces are not exact, or a fixed parameter differs from ``base``, every block
    is computed from the model.

    Parameters
    ----------
    model : SuspensionModel
    base : mapping
        Parameter values (SI); the fixed ones are held at these values.
    free : list of str
        Free parameter names.
    """

    def __init__(self, model: SuspensionModel, base: Mapping[str, float], free: list[str]) -> None:
        self.model = model
        self.free = list(free)
        self.names = [q.name for q in model.params]
        fset = set(self.free)
        self._ifree = [self.names.index(k) for k in self.free]
        self._ifix = [i for i, k in enumerate(self.names) if k not in fset]
        self._vfix = [float(base[self.names[i]]) for i in self._ifix]
        n = model.n_states
        nr = len(model.roads)
        self._n, self._nr = n, nr
        self.affine_ab = False
        self.affine_bz = False
        if not self.free:
            return
        try:
            pieces = model.affine({k: float(base[k]) for k in self.names}, self.free)
        except (np.linalg.LinAlgError, ValueError, ZeroDivisionError, FloatingPointError):
            return
        if not pieces.exact:
            return
        nq = n // 2
        # the pieces' acceleration rows laid out as [A | B | Bz], each block column-major
        # (the order LAPACK wants A in): theta -> c0 + theta @ D
        A0, B0 = pieces.state_space(np.zeros(len(self.free)))
        dA = np.zeros((len(self.free), n, n))
        dB = np.zeros((len(self.free), n, 2 * nr))
        dA[:, nq:, :] = pieces.dAB[:, :, :n]
        dB[:, nq:, :] = pieces.dAB[:, :, n:]
        Bv0 = B0[:, nr:]
        scale = float(np.abs(Bv0).max()) + 1e-300
        th0 = np.abs(pieces.theta(pieces.base))
        self.affine_ab = True
        self.affine_bz = bool(np.all(np.abs(dB[:, :, nr:]) * th0[:, None, None]
                                     <= 1e-12 * scale))
        blocks0 = [A0.ravel(order="F"), B0.ravel(order="F")]
        blocksD = [np.stack([a.ravel(order="F") for a in dA]),
                   np.stack([b.ravel(order="F") for b in dB])]
        if self.affine_bz:
            # Bz = A B_v + B_r with B_v fixed: affine in theta
            blocks0.append((A0 @ Bv0 + B0[:, :nr]).ravel(order="F"))
            blocksD.append(np.stack([(a @ Bv0 + b[:, :nr]).ravel(order="F")
                                     for a, b in zip(dA, dB)]))
        self._c0 = np.concatenate(blocks0)
        self._D = np.ascontiguousarray(np.concatenate(blocksD, axis=1))

    def _from_model(self, vals: list[float]) -> tuple[FloatArray, FloatArray, FloatArray]:
        A, B = self.model.state_space(dict(zip(self.names, vals)))
        nr = self._nr
        return A, B, A @ B[:, nr:] + B[:, :nr]

    def __call__(self, p: Mapping[str, float]) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(A, B, Bz)`` at ``p`` (SI parameters)."""
        return self.from_values([p[k] for k in self.names])[:3]

    def from_values(self, vals: list[float]
                    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """``(A, B, Bz, [B | Bz])`` for the values of every parameter in model order.

        ``vals`` follows ``names``. Affine blocks are Fortran-ordered views of one vector
        (as LAPACK wants ``A``); the last item is the input matrices side by side,
        ``[B_r | B_v | Bz]`` (n x 3 n_roads).
        """
        if self.affine_ab and [vals[i] for i in self._ifix] == self._vfix:
            f = self._c0 + np.array([vals[i] for i in self._ifree]) @ self._D
            n, nr = self._n, self._nr
            k1 = n * n
            k2 = k1 + 2 * n * nr
            A = f[:k1].reshape((n, n), order="F")
            B = f[k1:k2].reshape((n, 2 * nr), order="F")
            if self.affine_bz:
                BB = f[k1:].reshape((n, 3 * nr), order="F")
                return A, B, BB[:, 2 * nr:], BB
            Bz = A @ B[:, nr:] + B[:, :nr]
            return A, B, Bz, np.concatenate([B, Bz], axis=1)
        A, B, Bz = self._from_model(vals)
        return A, B, Bz, np.concatenate([B, Bz], axis=1)


@dataclass
class _Pattern:
    """Bookkeeping of one eigenvalue pattern (which ``dgeev`` columns form which mode)."""

    k1: list[int]  # column of the real part (or of the real eigenvector) of each kept mode
    k2: list[int]  # column of the imaginary part (= k1 for a real mode)
    is_pair: list[bool]
    fac: FloatArray  # (m,) 2 for a complex pair, 1 for a real mode
    pairs: np.ndarray  # indices of the complex modes
    sel_v: np.ndarray  # (n, m) complex: V = vr @ sel_v
    sel_cv: np.ndarray  # (n, m) complex: (C V) fac = (C vr) @ sel_cv
    k1a: np.ndarray  # k1 as an index array
    k2a: np.ndarray  # k2 as an index array
    pair_mask: FloatArray  # (m,) 1.0 for a complex pair, 0.0 for a real mode
    ix_pairs: tuple[np.ndarray, ...]  # np.ix_(pairs, pairs)


@dataclass
class _Traj:
    """Road-driven modal trajectory ``sum_j (Ca_j E^k Q_j[k] - Cb_j r_j[k]) + cc E^k``."""

    Wf: np.ndarray  # (m, N) sum over roads j of Ca_j E^k Q_j[k], Ca = a0 + a1
    Cb: np.ndarray  # (m, nr) a0
    cc: np.ndarray  # (m,) w0 - a1 r[0]


@dataclass
class _Eval:
    """One lean evaluation, kept for reuse at the same parameters.

    The residual ``R`` is formed on first use (``R0`` less the fitted free response): the
    cost ``ss`` does not need it unless ``_evaluate`` formed it for precision.
    """

    key: tuple[float, ...]
    vr: FloatArray  # (n, n) LAPACK right eigenvectors (real and imaginary parts)
    pat: _Pattern
    A: FloatArray
    B: FloatArray
    P: np.ndarray  # (m, N) powers E^k
    traj: _Traj | None  # the road-driven part of the modal trajectory (None: no road)
    coef: np.ndarray  # (m,) complex modal coefficients of the fitted free response
    R0: FloatArray  # (p, N) residual before the free response, measured - forced
    CV: np.ndarray  # (p, m) complex fitted channels per mode
    ss: float  # sum of squared final residuals
    _R: FloatArray | None = None

    @property
    def R(self) -> FloatArray:
        """Final residual (p, N), measured - predicted (formed once, on first use)."""
        R = self._R
        if R is None:
            R = self._R = self.R0 - (self.CV @ (self.coef[:, None] * self.P)).real
        return R

    @property
    def c(self) -> np.ndarray:
        """Complex free modal coefficients of the initial state (m,).

        The fit absorbed the forced response's own free term ``(w0 - a1 r[0]) E^k``;
        it is taken out again here.
        """
        c = self.coef
        return c if self.traj is None else c - self.traj.cc

    def modal(self, r: FloatArray) -> np.ndarray:
        """Complete modal trajectory (m, N): road-driven part plus the fitted free response."""
        W = self.coef[:, None] * self.P
        if self.traj is not None:
            W += self.traj.Wf
            W -= self.traj.Cb @ r
        return W


@dataclass
class GaussNewton:
    """Outcome of :meth:`WindowProblem.gauss_newton`."""

    params: dict[str, float] | None  # the parameters reached (SI); None: no step taken
    jacobian: FloatArray | None  # residual Jacobian (log-parameters) at the start
    nfev: int  # evaluations used


@dataclass
class WindowProblem(OutputErrorProblem):
    """:class:`~estimator.identify.OutputErrorProblem` with a lean evaluation path.

    Parameters are those of the parent class plus ``ssmap``, an optional
    :class:`StateSpaceMap` built once for the monitor. The lean path is taken when the time
    grid is uniform, every fitted sample is finite, the weights are 1 and
    ``x0="estimate"`` (attribute ``lean``); ``n_fallback`` counts evaluations that needed
    the parent's path. Its lean path maps the motion channels only: measured ride heights
    are left out of the window's cost (with a warning).
    """

    compares_ride_heights: ClassVar[bool] = False

    ssmap: StateSpaceMap | None = None
    lean: bool = field(init=False, default=False)
    n_fallback: int = field(init=False, default=0)
    #: ``(free, p_hat, J)`` of the last lean :meth:`finish`: ``J`` (p N x n_free) the
    #: derivative of the predicted fitted channels (channel-major rows) with respect to
    #: the log-parameters at ``p_hat``
    jacobian: tuple[list[str], dict[str, float], FloatArray] | None = field(
        init=False, default=None)

    def __post_init__(self) -> None:
        super().__post_init__()
        m = self.model
        self._cache: dict[tuple[float, ...], _Eval] = {}
        self.lean = bool(self._full and self.h is not None and self._unit_w
                         and isinstance(self.x0, str) and self.x0 == "estimate"
                         and self.t.size >= 2)
        if not self.lean or self.h is None:  # (lean implies a uniform grid, h is not None)
            return
        if self.ssmap is None or self.ssmap.model is not m:
            self.ssmap = StateSpaceMap(m, {q.name: q.default for q in m.params}, [])
        self._ssmap: StateSpaceMap = self.ssmap  # the lean path's map
        nr = len(m.roads)
        self._nr = nr
        self._N = int(self.t.size)
        self._names = [q.name for q in m.params]
        self._r = np.ascontiguousarray(self.U[:, :nr].T)  # (nr, N)
        self._r0 = self._r[:, 0].copy()
        self._rc = self._r.astype(complex)
        self._hf = float(self.h)
        self._UT = np.ascontiguousarray(self.U.T)  # (2 nr, N)
        self._Yflat = np.ascontiguousarray(self.Ymeas.T).ravel()  # (p N,) channel-major
        self._road = bool(np.any(self._r))
        self._YT = np.ascontiguousarray(self.Ymeas.T)  # (p, N)
        self._rdot = bool(np.any(self.U[:, nr:]))
        # fitted channels that are states (positions/velocities): CV = V[rows] * fac
        self._rows = [i + (self._nq if order == 1 else 0) for i, order in self._kind]
        self._state_rows = all(order < 2 for _, order in self._kind)
        self._prow = len(self._rows)
        self._rows_are_range = self._rows == list(range(self._prow))
        self._pos_only = all(order == 0 for _, order in self._kind)
        # every measured model channel (for the RMS of all channels at the optimum)
        self._all = [c for c in m.channels if c in self.meas.measured]
        self._all_kind = channel_kinds(m.coords, self._all)
        self._Mall = np.array([np.asarray(self.meas.measured[c], dtype=float) for c in self._all])
        # RMS of each fitted channel (the identifiability scale of a noise-free channel)
        self._ref = np.sqrt((self.Ymeas0 * self.Ymeas0).mean(axis=0))

    # ---- helpers -------------------------------------------------------------------------
    def _maps(self, kinds: list[tuple[int, int]], A: FloatArray, B: FloatArray
              ) -> tuple[FloatArray, FloatArray]:
        """Output maps ``y = Cm x + Dm u`` of the channels ``kinds``."""
        return output_maps(kinds, A, B, self._nq)

    def _pattern(self, wi: list[float]) -> _Pattern | None:
        """Mode bookkeeping for the eigenvalue pattern of ``dgeev`` (cached per pattern).

        ``None`` when the pattern is not a clean sequence of real eigenvalues and
        conjugate pairs (positive imaginary part first), as LAPACK returns them.
        """
        sig = tuple(0 if v == 0.0 else (1 if v > 0 else -1) for v in wi)
        got = _PATTERNS.get(sig)
        if got is not None:
            return got
        k1: list[int] = []
        k2: list[int] = []
        j = 0
        n = len(sig)
        while j < n:
            if sig[j] == 0:
                k1.append(j)
                k2.append(j)
                j += 1
            elif sig[j] > 0 and j + 1 < n and sig[j + 1] < 0:
                k1.append(j)
                k2.append(j + 1)
                j += 2
            else:
                return None
        mm = len(k1)
        is_pair = [x != y for x, y in zip(k1, k2)]
        fac = np.array([2.0 if q else 1.0 for q in is_pair])
        sel_v = np.zeros((n, mm), dtype=complex)  # V = vr @ sel_v
        for i, (x, y) in enumerate(zip(k1, k2)):
            sel_v[x, i] = 1.0
            if is_pair[i]:
                sel_v[y, i] = 1j
        got = _Pattern(k1, k2, is_pair, fac, np.flatnonzero(is_pair), sel_v, sel_v * fac,
                       np.array(k1), np.array(k2), np.array(is_pair, dtype=float),
                       np.ix_(np.flatnonzero(is_pair), np.flatnonzero(is_pair)))
        _PATTERNS[sig] = got
        return got

    # ---- the lean evaluation ------------------------------------------------------------
    def _evaluate(self, p: Mapping[str, float]) -> _Eval | None:
        """Residual of the fitted channels at ``p`` by the lean path (``None``: not covered).

        Arrays are laid out modes x samples so every elementwise operation runs over
        contiguous rows of ``N`` samples; per-mode scalars are Python complex numbers, and
        the complex eigenvectors are never formed (real products with LAPACK's real and
        imaginary parts instead).
        """
        vals = [p[k] for k in self._names]
        key = tuple(vals)
        got = self._cache.get(key)
        if got is not None:
            return got
        A, B, Bz, BB = self._ssmap.from_values(vals)
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
                return None  # within rounding of the real axis: the parent decides
        pat = self._pattern(wil)
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
        # cond_1(V) <= sqrt(n) sum_i fac_i / |u_i^H v_i| for unit eigenvectors; the exact
        # test of modal_form only when that bound is not already below the limit
        if math.sqrt(n) * bound > MAX_V_COND:
            V = vr @ pat.sel_v
            Vinv = (vl @ pat.sel_v).conj().T / np.array(uv)[:, None]
            if (np.abs(V).sum(axis=0).max() * (np.abs(Vinv) * pat.fac[:, None]).sum(axis=0).max()
                    > MAX_V_COND):
                return None
        mm = len(uv)
        N = self._N
        h = self._hf
        lam = [complex(wrl[j], wil[j]) for j in pat.k1]
        if max(-x.real for x in lam) * h * (N - 1) > MAX_DECAY_EXPONENT:
            return None
        # fitted channels per mode: CV = (Cm V) fac
        if self._state_rows:
            CV = (vr[:self._prow] if self._rows_are_range else vr[self._rows]) @ pat.sel_cv
            Cm = Dm = None
        else:
            Cm, Dm = self._maps(self._kind, A, B)
            CV = (Cm @ vr) @ pat.sel_cv
        # per mode: E = exp(lam h), first-order-hold weights (as suspid.simulate._foh_weights)
        # and, with b = V^-1 Bz and w0 = -V^-1 Bv r[0] (forced response from rest),
        #   w[k] = E^k (w0 + sum_{l<k} b (g0 r[l] + g1 r[l+1]) E^-(l+1))
        #        = (a0 + a1) E^k Q[k] - a0 r[k] + (w0 - a1 r[0]) E^k,
        # q[l] = r[l] E^-l, Q = cumsum(q), a0 = b g0 / E, a1 = b g1 (w[0] = w0 exactly).
        # The last term is a free response: the least-squares initial state absorbs it, so
        # it is left out of the residual and subtracted from the free coefficients after.
        road = self._road
        lam_a = np.array(lam)
        El_a, g0a, g1a = foh_weights_modes(lam_a, h)  # (m,) each
        if road:
            # rows of V^-1 [Br | Bv | Bz] from the left eigenvectors' real and imaginary
            # parts: (a - ib)^T B / (u_i^H v_i)
            VZ = vl.T @ BB
            X = (VZ[pat.k1a] - 1j * (VZ[pat.k2a] * pat.pair_mask[:, None])) / np.array(uv)[:, None]
            Xb = X[:, 2 * nr:]  # b = V^-1 Bz
            Cb = Xb * (g0a / El_a)[:, None]  # a0
            a1 = Xb * g1a[:, None]
            Ca = Cb + a1  # a0 + a1
            cc = -((X[:, nr:2 * nr] + a1) @ self._r0)  # w0 - a1 r[0], w0 = -V^-1 Bv r[0]
        P = np.empty((mm, N), dtype=complex)
        P[:] = El_a[:, None]
        P[:, 0] = 1.0
        np.cumprod(P, axis=1, out=P)
        if road:
            # the roads summed first (the trajectory is linear in them):
            #   Wf[k] = sum_j Ca_j E^k Q_j[k] = E^k cumsum_l((sum_j Ca_j r_j[l]) E^-l)
            Wf = Ca @ self._rc
            np.divide(Wf, P, out=Wf)
            np.cumsum(Wf, axis=1, out=Wf)
            Wf *= P
            # R = Y - Re(CV Wf - (CV Cb) r)
            R = self._YT - (CV @ Wf).real
            R += (CV @ Cb).real @ self._r
            if not self._pos_only:
                CB = B[self._rows, nr:] if Cm is None else Cm @ B[:, nr:]
                R -= CB @ self._r
                if Dm is not None and self._rdot:
                    R -= Dm @ self._UT
            traj = _Traj(Wf, Cb, cc)
        else:
            R = self._YT.copy()
            traj = None
        # least-squares free modal coefficients. The regressors are Re(CV[:, i] E_i^k) for
        # every mode, then -Im(...) for the complex ones; with x = CV_ci E_i^k and
        # y = CV_cj E_j^k their Gram matrix follows from the sums over channels and samples
        #   S1 = sum x y = (CV^T CV)_ij g(E_i E_j),  S2 = sum x conj(y) = (CV^H CV)*_ij ...,
        # g(z) = sum_{k<N} z^k = (1 - z^N) / (1 - z), as Re x Re y = Re(S1 + S2) / 2,
        # Im x Im y = Re(S2 - S1) / 2, Re x Im y = Im(S1 - S2) / 2 -- no regressor matrix
        sAB = np.empty((2, mm, mm), dtype=complex)  # (lam_i + lam_j) h, (lam_i + lam_j*) h
        np.add(lam_a[:, None], lam_a[None, :], out=sAB[0])
        np.add(lam_a[:, None], lam_a.conj()[None, :], out=sAB[1])
        sAB *= h
        gAB = np.expm1(N * sAB)
        gAB /= np.expm1(sAB)
        CC = CV.T @ np.concatenate([CV, CV.conj()], axis=1)  # [CV^T CV | CV^T conj(CV)]
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
        y = (CV * (R @ P.T)).sum(axis=0)
        rhs = np.concatenate([y.real, -y.imag[pairs]])
        proj = rhs @ vec
        sol = vec @ (proj / ev)  # not finite only if R is: the cost is then inf
        coef = sol[:mm].astype(complex)
        if npair:
            coef[pairs] += 1j * sol[mm:]
        # the cost without the residual pass: ||R0 - G sol||^2 = ||R0||^2 - rhs . sol at the
        # least-squares sol (Gram sol = rhs); explicit when the two terms nearly cancel
        r0 = R.ravel()
        r0sq = float(r0 @ r0)
        ss = r0sq - float(proj @ (proj / ev))
        out = _Eval(key, vr, pat, A, B, P, traj, coef, R, CV, ss)
        if not ss >= SS_GUARD * r0sq:
            r = out.R.ravel()
            out.ss = float(r @ r)
        cache = self._cache
        if len(cache) >= CACHE_SIZE:
            del cache[next(iter(cache))]  # oldest first
        cache[key] = out
        return out

    def _x0(self, ev: _Eval) -> FloatArray:
        """Initial state of an evaluation (the free part; the forced part starts at rest)."""
        return np.real((ev.vr @ ev.pat.sel_v) @ (ev.c * ev.pat.fac))

    # ---- the parent's interface -----------------------------------------------------------
    def predict(self, p: Mapping[str, float]) -> Prediction:
        """Predict the fitted channels for ``p`` with the best ``x0`` (lean path if possible)."""
        if self.lean:
            ev = self._evaluate(p)
            if ev is not None:
                res = ev.R.T.copy()
                return Prediction(Y=self.Ymeas - res, x0=self._x0(ev), residual=res)
            self.n_fallback += 1
        return super().predict(p)

    def residual_vector(self, p: Mapping[str, float]) -> FloatArray:
        """Residuals of the fitted samples, flattened sample-major (as the parent's)."""
        if self.lean:
            ev = self._evaluate(p)
            if ev is not None:
                return ev.R.T.ravel()
            self.n_fallback += 1
        return super().residual_vector(p)

    def normalized_ss(self, p: Mapping[str, float]) -> float:
        """Sum of squared residuals divided by the data's (dimensionless, 1 = no fit)."""
        if self.lean:
            try:
                ev = self._evaluate(p)
            except (np.linalg.LinAlgError, ValueError, FloatingPointError, OverflowError,
                    ZeroDivisionError):
                return math.inf
            if ev is not None:
                v = ev.ss / self.scale
                return v if math.isfinite(v) else math.inf
            self.n_fallback += 1
        return super().normalized_ss(p)

    def _all_outputs(self, ev: _Eval) -> FloatArray:
        """Every measured model channel (rows) of an evaluation, from its estimated ``x0``."""
        Cm, Dm = self._maps(self._all_kind, ev.A, ev.B)
        CV = (Cm @ ev.vr) @ ev.pat.sel_cv
        Y = (CV @ ev.modal(self._r)).real + (Cm @ ev.B[:, self._nr:]) @ self._r + Dm @ self._UT
        return Y

    def all_outputs(self, p: Mapping[str, float], x0: FloatArray) -> dict[str, FloatArray]:
        """Every measured channel at ``p`` from the initial state ``x0`` (SI).

        Reuses the lean evaluation at ``p`` when ``x0`` is its estimated initial state;
        otherwise the core's simulation (:func:`suspid.simulate.simulate_states`).
        """
        if self.lean:
            ev = self._evaluate(p)
            if ev is not None and np.array_equal(self._x0(ev), np.asarray(x0, dtype=float)):
                Y = self._all_outputs(ev)
                return {c: Y[j] for j, c in enumerate(self._all)}
        X = simulate_states(self.model, p, self.t, self.U, np.asarray(x0, dtype=float))
        out = outputs(self.model, p, X, self.U)
        return {c: out[c] for c in self.model.channels if c in self.meas.measured}

    # ---- result at the optimum ----------------------------------------------------------------
    def finish(self, params: Parameters, p_hat: Mapping[str, float], nfev: int,
               converged: bool, simplex: list[Mapping[str, float]] | None = None,
               rel_step: float = 1e-6, jacobian: FloatArray | None = None) -> IdentResult:
        """:func:`estimator.identify.finish` for a window: result, stderr, identifiability.

        Same quantities and formulas (RMS of every measured channel, per-channel residual
        variance, sandwich covariance of the log-parameters, identifiability verdict on the
        noise-normalised Jacobian), with the evaluations reused on the lean path:

        * the residual at ``p_hat`` is Nelder-Mead's best vertex (cached);
        * the Jacobian of the residuals with respect to the log-parameters is the *secant*
          through Nelder-Mead's final simplex (``simplex``: its vertices, best first, all
          evaluated already): ``J = dR D^-1`` with ``D`` the edges from the best vertex
          (log units) and ``dR`` the residual differences. With edges of ~``xatol``
          (0.2 %) its truncation error is ~0.1-1 % of the Jacobian, i.e. of ``stderr_fit``
          (itself a small part of ``stderr`` next to the ``sigma_floor``). When an edge
          is longer than :data:`SECANT_MAX_EDGE`, the edge matrix is ill-conditioned
          (condition number > :data:`SECANT_MAX_COND`) or a vertex was not evaluated on
          the lean path, ``jacobian`` when given (the Gauss-Newton steps' forward
          difference, within :data:`GAUSS_NEWTON_MAX_STEP` of ``p_hat``), else a forward
          difference (``rel_step``, ``n_free`` evaluations) is used instead.

        Not lean: :func:`estimator.identify.finish` (central differences).

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
        ev = self._evaluate(p_hat) if self.lean else None
        if ev is None or not free:
            return finish(self, params, p_hat, nfev, converged, with_stderr=True)
        model = self.model
        pch, N = ev.R.shape
        r0 = ev.R.ravel()
        x0 = self._x0(ev)
        Yall = self._all_outputs(ev)
        rms = dict(zip(self._all, np.sqrt(((self._Mall - Yall) ** 2).mean(axis=1)).tolist()))
        nf = len(free)
        J = self._secant(free, p_hat, r0, simplex)
        if J is None and jacobian is not None and jacobian.shape == (r0.size, nf):
            J = jacobian
        if J is None:
            J = self._forward_jacobian(free, p_hat, r0, rel_step)
            if J is None:
                return finish(self, params, p_hat, nfev, converged, with_stderr=True)
        # residual = y - yhat, so -d(residual) = d(yhat); rows channel-major (j*N + k)
        J = -J
        self.jacobian = (list(free), dict(p_hat), J)
        n_obs = pch * N
        ss = float(r0 @ r0)
        dof = max(n_obs - nf, 1) / n_obs
        sig2 = (ev.R * ev.R).sum(axis=1) / (N * dof)
        warnings = list(self.meas.warnings) + list(self.warnings)
        scale_c = np.sqrt(np.where(sig2 > 0, sig2, 0.0))
        ref = self._ref
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
        nss = ss / self.scale
        aic = n_obs * math.log(max(nss, 1e-300) / n_obs) + 2 * nf
        bic = n_obs * math.log(max(nss, 1e-300) / n_obs) + nf * math.log(n_obs)
        if not converged:
            warnings.append("Nelder–Mead stopped on its evaluation budget before converging")
        return IdentResult(
            model=model.name, params={k: float(v) for k, v in p_hat.items()},
            fixed=params.fixed, stderr=stderr, cost=self.seed_cost(ss), nfev=nfev,
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
            The parameters reached (``None``: not on the lean path or no step lowered the
            cost), the Jacobian at ``p_hat`` (``None`` off the lean path) and the
            evaluations used.
        """
        ev = self._evaluate(p_hat) if self.lean else None
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
                eq = self._evaluate(q)
            except (np.linalg.LinAlgError, ValueError, FloatingPointError, OverflowError,
                    ZeroDivisionError):
                eq = None
            if eq is None or not eq.ss < ss:
                break
            u, ss, best, r = un, eq.ss, q, eq.R.ravel()
        return GaussNewton(best, J, nfev)

    def _forward_jacobian(self, free: list[str], p_hat: Mapping[str, float], r0: FloatArray,
                          rel_step: float) -> FloatArray | None:
        """Residual Jacobian (log-parameters) by forward differences on the lean path.

        ``r0`` is the residual at ``p_hat`` (channel-major); one evaluation per free
        parameter, step ``rel_step`` (log units). ``None`` when an evaluation leaves the
        lean path.
        """
        cols = []
        for k in free:
            q = dict(p_hat)
            q[k] = p_hat[k] * math.exp(rel_step)
            ek = self._evaluate(q)
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
            ek = self._cache.get(tuple([q[k] for k in self._names]))
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
        """Whether :meth:`drift_residual` applies (lean window, fitted channels are states)."""
        return bool(self.lean and self._state_rows)

    def drift_residual(self, p: Mapping[str, float], rates: Mapping[str, float],
                       t_ref: float, chunk_s: float) -> FloatArray | None:
        """Residual (p, N) of a window whose parameters drift linearly in time.

        ``theta_k(t) = p_k (1 + g_k (t - t_ref))`` for every ``k`` in ``rates`` (``g_k``
        relative rate, 1/s), the others constant at ``p``. The window is cut into chunks of
        ``chunk_s``; in each ``A`` and ``Bz`` are taken at the chunk's middle time and the
        first-order-hold road is discretised exactly (one matrix exponential per chunk).
        The initial state is fitted by least squares as on the constant path; with every
        rate zero the residual equals the lean evaluation's to rounding. ``None`` when
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
        t = self.t
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
            A, B, Bz, _ = self._ssmap.from_values(v)
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
        R = self._Yflat - Yp[:, :, n].T.ravel()
        if not self._pos_only and Bv is not None:
            # velocity channels: x = z + B_v r (B_v fixed on this path)
            R -= (Bv[rows] @ self._r).ravel()
        sol, *_ = np.linalg.lstsq(G, R, rcond=None)
        R = R - G @ sol
        return R.reshape(len(rows), N)

    def lean_residual(self, p: Mapping[str, float]) -> FloatArray | None:
        """Residual (p, N) of the lean evaluation at ``p`` (cached), or ``None``."""
        ev = self._evaluate(p) if self.lean else None
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
        the lean evaluation's state trajectory at ``p`` (the simulator's ``z = x - B_v r``
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
            lean path or ``B_v`` depends on one of ``names``.
        """
        if not self.drift_ok or not names:
            return None
        ev = self._evaluate(p)
        if ev is None:
            return None
        nr = self._nr
        N = self._N
        h = self._hf
        vals = [float(p[k]) for k in self._names]
        A, B, Bz, _ = self._ssmap.from_values(vals)
        dA, dBz = [], []
        for k in names:
            i = self._names.index(k)
            eps = 1e-6
            v = list(vals)
            v[i] = vals[i] * (1.0 + eps)
            A1, B1, Bz1, _ = self._ssmap.from_values(v)
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
        tt = self.t - t_ref
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
        # first-order-hold weights per mode (as the lean evaluation's)
        _, g0, g1 = foh_weights_modes(lam, h)
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
        # column rank: the lean evaluation checked their Gram matrix's condition number)
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
        v = float(r @ r) / self.scale
        return v if math.isfinite(v) else math.inf

    def drift_stderr(self, p: Mapping[str, float], free: list[str], rates: Mapping[str, float],
                     t_ref: float, chunk_s: float, rel_step: float = 1e-4,
                     fixed_rates: Mapping[str, float] | None = None,
                     rate_prior_sd: float | None = None, R0: FloatArray | None = None
                     ) -> dict[str, float] | None:
        """Gauss-Newton standard errors (SI) of the free parameters at ``t_ref`` with the
        drift ``rates`` free as well (forward differences, noise per channel from the
        residual); ``fixed_rates`` drift too but are known; ``rate_prior_sd`` (1/s) adds a
        prior of that standard deviation on each free rate. ``R0``: the residual at ``p``
        when already computed (as :meth:`drift_residual` returns it).
        """
        known = dict(fixed_rates or {})
        rates = dict(rates)

        def resid(q: Mapping[str, float], g: Mapping[str, float]) -> FloatArray | None:
            return self.drift_residual(q, {**known, **g}, t_ref, chunk_s)

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
