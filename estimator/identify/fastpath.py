"""The fast path's pieces: eigenvalue patterns, the forced trajectory, one evaluation's
results and the affine state-space layout (:meth:`OutputErrorProblem.evaluate`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from suspid.models.base import AffinePieces, FloatArray


#: largest ``max(-Re(lam)) h N`` for which ``E**-N`` is formed (e^600 ~ 1e260 < 1.8e308)
MAX_DECAY_EXPONENT = 600.0
#: Gram-matrix condition number above which the initial state is solved explicitly
MAX_GRAM_COND = 1e12
#: fraction of ``||R0||^2`` below which the fast cost ``||R0||^2 - rhs . sol`` cancels and the
#: residual is formed explicitly (noise-free data at its optimum)
SS_GUARD = 1e-4
#: most fast evaluations cached per problem (a monitor window's Nelder-Mead final simplex
#: is among the latest) ...
CACHE_SIZE = 32
#: ... and at most this many bytes of them (a long identify record keeps fewer)
CACHE_BYTES = 8 << 20

_PATTERNS: dict[tuple[int, ...], "_Pattern"] = {}


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


def eigen_pattern(wi: list[float]) -> _Pattern | None:
    """Mode bookkeeping for the eigenvalue pattern of ``dgeev`` (cached per pattern).

    ``None`` when the pattern is not a clean sequence of real eigenvalues and conjugate
    pairs (positive imaginary part first), as LAPACK returns them.
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
    pairs = np.flatnonzero(is_pair)
    got = _Pattern(k1, k2, is_pair, fac, pairs, sel_v, sel_v * fac, np.array(k1),
                   np.array(k2), np.array(is_pair, dtype=float), np.ix_(pairs, pairs))
    _PATTERNS[sig] = got
    return got


@dataclass
class ForcedTrajectory:
    """Road-driven modal trajectory ``sum_j (Ca_j E^k Q_j[k] - Cb_j r_j[k]) + cc E^k``."""

    Wf: np.ndarray  # (m, N) sum over roads j of Ca_j E^k Q_j[k], Ca = a0 + a1
    Cb: np.ndarray  # (m, nr) a0
    cc: np.ndarray  # (m,) w0 - a1 r[0]


@dataclass
class Evaluation:
    """One fast evaluation (:meth:`OutputErrorProblem.evaluate`), kept for reuse at the same
    parameters.

    The residual ``R`` is formed on first use (``R0`` less the fitted free response): the
    cost ``ss`` does not need it unless the evaluation formed it for precision.
    """

    key: tuple[float, ...]
    vr: FloatArray  # (n, n) LAPACK right eigenvectors (real and imaginary parts)
    pat: _Pattern
    A: FloatArray
    B: FloatArray
    P: np.ndarray  # (m, N) powers E^k
    traj: ForcedTrajectory | None  # the road-driven part of the modal trajectory (None: no road)
    coef: np.ndarray  # (m,) complex modal coefficients of the fitted free response
    R0: FloatArray  # (p, N) residual before the free response, measured - forced
    CV: np.ndarray  # (p, m) complex fitted channels per mode
    ss: float  # weighted sum of squared final residuals
    _R: FloatArray | None = None

    @property
    def R(self) -> FloatArray:
        """Final residual (p, N), measured - predicted (unweighted, formed on first use)."""
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
        """Complete modal trajectory (m, N): road-driven part plus the fitted free response
        (``r`` the roads, (nr, N))."""
        W = self.coef[:, None] * self.P
        if self.traj is not None:
            W += self.traj.Wf
            W -= self.traj.Cb @ r
        return W


class StateSpaceLayout:
    """``vals -> (A, B, Bz, [B | Bz])`` as one product, from a model's exact affine pieces.

    The pieces' acceleration rows (:class:`~suspid.models.base.AffinePieces`) laid out once
    as the column-major blocks ``[A | B | Bz]`` (the order LAPACK wants ``A`` in):
    ``c0 + theta @ D``. ``Bz = A B_v + B_r`` is affine too when ``B_v`` (tyre damping over
    wheel mass) does not move with the free parameters; otherwise it is formed per call.

    Parameters
    ----------
    pieces : AffinePieces
        Exact pieces (``pieces.exact``).
    names : list of str
        Every parameter of the model, in the order of the values passed.
    n_roads : int
    """

    def __init__(self, pieces: AffinePieces, names: list[str], n_roads: int) -> None:
        self.pieces = pieces
        free = list(pieces.names)
        fset = set(free)
        self._ifree = [names.index(k) for k in free]
        self._ifix = [i for i, k in enumerate(names) if k not in fset]
        self._vfix = [float(pieces.base[names[i]]) for i in self._ifix]
        nq = pieces.nq
        n = 2 * nq
        nr = n_roads
        self._n, self._nr = n, nr
        A0, B0 = pieces.state_space(np.zeros(len(free)))
        dA = np.zeros((len(free), n, n))
        dB = np.zeros((len(free), n, 2 * nr))
        dA[:, nq:, :] = pieces.dAB[:, :, :n]
        dB[:, nq:, :] = pieces.dAB[:, :, n:]
        Bv0 = B0[:, nr:]
        scale = float(np.abs(Bv0).max()) + 1e-300
        th0 = np.abs(pieces.theta(pieces.base))
        self.affine_bz = bool(np.all(np.abs(dB[:, :, nr:]) * th0[:, None, None]
                                     <= 1e-12 * scale))
        blocks0 = [A0.ravel(order="F"), B0.ravel(order="F")]
        blocksD = [np.stack([a.ravel(order="F") for a in dA]),
                   np.stack([b.ravel(order="F") for b in dB])]
        if self.affine_bz:
            blocks0.append((A0 @ Bv0 + B0[:, :nr]).ravel(order="F"))
            blocksD.append(np.stack([(a @ Bv0 + b[:, :nr]).ravel(order="F")
                                     for a, b in zip(dA, dB)]))
        self._c0 = np.concatenate(blocks0)
        self._D = np.ascontiguousarray(np.concatenate(blocksD, axis=1))

    def applies(self, vals: Sequence[float]) -> bool:
        """Whether every fixed parameter of ``vals`` is at the pieces' base value."""
        return [vals[i] for i in self._ifix] == self._vfix

    def __call__(self, vals: Sequence[float]
                 ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """``(A, B, Bz, [B | Bz])``: Fortran-ordered views of one vector."""
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



def re_dot(P: np.ndarray, X: np.ndarray) -> FloatArray:
    """``Re(P @ X)`` for a C-contiguous ``P`` (N, m) as one real product.

    A complex ``P`` is read as the real (N, 2 m) matrix of its interleaved real and
    imaginary parts, so ``Re(P @ X) = P_real_view @ [Re X; -Im X]`` (rows interleaved):
    one BLAS ``dgemm`` on contiguous memory, no copies of the real and imaginary parts.
    """
    if P.dtype.kind != "c":
        return np.asarray(P @ X.real)
    m, p = X.shape
    Xs = np.empty((2 * m, p))
    Xs[0::2] = X.real
    Xs[1::2] = -X.imag if X.dtype.kind == "c" else 0.0
    return np.asarray(P.view(np.float64) @ Xs)
