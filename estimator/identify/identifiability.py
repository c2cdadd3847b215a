"""Identifiability verdict from the log-parameter Jacobian at the optimum.

A (numerically) zero relative singular value is a direction that leaves the response
unchanged; its right singular vector names the parameters (classically the common scale
of every mass, damper and spring).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from suspid.models.base import FloatArray

#: relative singular value below which a direction is unidentifiable (noise-free data give
#: ~1e-9 from finite-difference error; real ill-conditioning of useful data stays above)
RANK_TOL = 1e-6
#: relative singular value below which the combination is reported as poorly determined
WEAK_TOL = 1e-3


@dataclass
class Identifiability:
    """Verdict on the free parameters: the relative singular values (largest = 1), one
    warning per unidentifiable or weak combination naming the parameters, and each
    unidentifiable direction in log space as ``parameter -> component``.
    """

    identifiable: bool
    singular_values: list[float]
    warnings: list[str] = field(default_factory=list)
    null_directions: list[dict[str, float]] = field(default_factory=list)


def _describe(names: list[str], v: FloatArray) -> tuple[str, str, dict[str, float]]:
    """``(subject, unidentifiable predicate, components)`` of a log-space direction."""
    v = v / np.max(np.abs(v))
    if v[np.argmax(np.abs(v))] < 0:
        v = -v
    involved = [(n, float(c)) for n, c in zip(names, v) if abs(c) > 0.1]
    comps = {n: round(c, 3) for n, c in involved}
    same = all(abs(c - 1.0) < 0.1 for _, c in involved)
    plist = ", ".join(n for n, _ in involved)
    if same and len(involved) > 1:
        return (f"the common scale of {plist}",
                f"{plist} can all be scaled by one common factor without changing the response "
                f"(only their ratios are identifiable)", comps)
    combo = " + ".join(f"{c:+.2f}*log({n})" for n, c in involved)
    return (f"the combination {combo}", f"the combination {combo} does not change the response",
            comps)


def _null_warning(text: str, comps: dict[str, float], kinds: dict[str, str]) -> str:
    masses = [n for n in comps if kinds.get(n) in ("mass", "inertia")]
    fix = masses[0] if masses else next(iter(comps))
    return (f"unidentifiable: {text}; fix one of them (e.g. --fix {fix}=VALUE) to make the "
            f"rest identifiable")


def assess(J: FloatArray, names: list[str], kinds: dict[str, str],
           structural: tuple[str, ...] | list[str] = ()) -> Identifiability:
    """Judge identifiability from the log-parameter Jacobian ``J`` (rows: residuals).

    Parameters
    ----------
    J : ndarray, shape (M, n_free)
        Sensitivity of the (weighted) residuals to log-parameters.
    names : list of str
        Free parameter names (columns of ``J``).
    kinds : dict
        ``name -> kind`` (mass, inertia, ...) to suggest which parameter to fix.
    structural : sequence of str
        Parameters whose common scale leaves every response unchanged
        (:attr:`SuspensionModel.scale_invariant`): with all free, that direction is
        unidentifiable exactly and the rest is judged on its orthogonal complement.
    """
    if J.size == 0 or len(names) == 0:
        return Identifiability(True, [])
    if not np.all(np.isfinite(J)):
        return Identifiability(False, [], ["sensitivity matrix is not finite at the optimum; "
                                           "the fit did not reach a valid model"])
    n = len(names)
    basis = np.eye(n)
    out = Identifiability(True, [])
    if structural and set(structural) <= set(names):
        v = np.array([1.0 if k in structural else 0.0 for k in names])
        _, text, comps = _describe(names, v)
        out.identifiable = False
        out.null_directions.append(comps)
        out.warnings.append(_null_warning(text, comps, kinds))
        # orthonormal basis of the complement of v: the last n - 1 columns of a QR of [v, I]
        q, _ = np.linalg.qr(np.column_stack([v / np.linalg.norm(v), np.eye(n)]))
        basis = q[:, 1:n]
    Jr = J @ basis
    if Jr.shape[1] == 0:
        out.singular_values = [0.0]
        return out
    # fewer rows than directions: the missing singular values are zeros (an SVD reports
    # only min(M, n) of them; the rows of the full Vt beyond M span the null space)
    _, s, Vt = np.linalg.svd(Jr, full_matrices=Jr.shape[0] < Jr.shape[1])
    s = np.concatenate([s, np.zeros(Vt.shape[0] - s.size)])
    if s[0] == 0:
        return Identifiability(False, [0.0] * n,
                               ["the measured channels do not depend on any free parameter"])
    rel = s / s[0]
    out.singular_values = [float(x) for x in rel] + ([0.0] if basis.shape[1] < n else [])
    for i, r in enumerate(rel):
        if r < WEAK_TOL:
            subject, text, comps = _describe(names, basis @ Vt[i])
            if r < RANK_TOL:
                out.identifiable = False
                out.null_directions.append(comps)
                out.warnings.append(_null_warning(text, comps, kinds))
            else:
                out.warnings.append(f"poorly identifiable (relative singular value {r:.1e}): "
                                    f"{subject} is only weakly determined by this data")
    return out
