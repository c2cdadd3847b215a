"""Lean linear algebra on the identifier's small matrices (n <= 14), same results as numpy's.

:func:`numpy.linalg.eig`, ``inv``, ``solve`` and ``cond`` spend more time in their checks,
type dispatch and ``errstate`` bookkeeping than in LAPACK when the matrix is 4 x 4 to
14 x 14, and the identifier calls them on every cost evaluation. These functions call the
same LAPACK-backed generalised ufuncs (``numpy.linalg._umath_linalg``) directly, so their
values are bit for bit numpy's; only the failure signalling differs where documented (a
failure returns ``None`` or non-finite values instead of raising). Every function also
takes a stack ``(k, n, n)`` of matrices (LAPACK runs once per matrix, the results equal
one-by-one calls), which the batched Jacobians use.

``tests/core/test_smalllinalg.py`` holds them to numpy's public functions.
"""
from __future__ import annotations

import numpy as np

# numpy's own LAPACK gufuncs: what numpy.linalg calls after its checks (numpy 1.x and 2.x)
from numpy.linalg import _umath_linalg as _ul


def eig(A: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Eigenvalues and right eigenvectors of real ``A`` (..., n, n), as :func:`numpy.linalg.eig`.

    Parameters
    ----------
    A : ndarray, shape (..., n, n)
        Real square matrices (units of 1/s for a state matrix).

    Returns
    -------
    (w, V) or None
        As :func:`numpy.linalg.eig`: real arrays when every eigenvalue of the whole stack
        is real, complex ones otherwise. ``None`` when ``A`` has a non-finite entry or
        LAPACK did not converge (where numpy raises ``LinAlgError``).
    """
    if not np.isfinite(A).all():
        return None
    with np.errstate(all="ignore"):
        w, V = _ul.eig(A, signature="d->DD")
    if not np.isfinite(w).all():  # LAPACK's failure: numpy fills NaN and raises
        return None
    if not w.imag.any():
        return w.real, V.real
    return w, V


def inv(A: np.ndarray) -> np.ndarray:
    """Inverse of ``A`` (..., n, n), as :func:`numpy.linalg.inv`; NaN where singular.

    Parameters
    ----------
    A : ndarray, shape (..., n, n)
        Real or complex square matrices.

    Returns
    -------
    ndarray, shape (..., n, n)
        The inverse (bit for bit numpy's); a singular matrix gives NaN entries where numpy
        raises ``LinAlgError``.
    """
    with np.errstate(all="ignore"):
        return _ul.inv(A, signature="D->D" if A.dtype.kind == "c" else "d->d")


def solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solution of ``A x = b`` for real ``A`` (n, n) and ``b`` (n,), as :func:`numpy.linalg.solve`.

    Parameters
    ----------
    A : ndarray, shape (n, n)
        Real square matrix.
    b : ndarray, shape (n,)
        Real right-hand side.

    Returns
    -------
    ndarray, shape (n,)
        The solution (bit for bit numpy's); NaN where ``A`` is singular (numpy raises).
    """
    with np.errstate(all="ignore"):
        return _ul.solve1(A, b, signature="dd->d")


def cond2(A: np.ndarray) -> float:
    """2-norm condition number of real ``A`` (n, n), as :func:`numpy.linalg.cond`.

    Parameters
    ----------
    A : ndarray, shape (n, n)
        Real square matrix without NaN.

    Returns
    -------
    float
        ``s_max / s_min`` of the singular values (dimensionless); ``inf`` for a singular
        matrix or when the SVD did not converge (numpy raises there).
    """
    with np.errstate(all="ignore"):
        s = _ul.svd(A, signature="d->d")
        r = float(s[0] / s[-1])
    return r if r == r else float("inf")
