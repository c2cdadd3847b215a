"""Identifiability verdict from the sensitivity (Jacobian) matrix at the optimum.

The Jacobian is taken with respect to log-parameters, so its columns are relative
sensitivities and its singular values compare across units. A (numerically) zero singular
value means a direction in parameter space that leaves the response unchanged; its right
singular vector names the parameters involved. For the linear models the classic case is
the *scale ambiguity*: multiplying every mass, damping and stiffness by the same factor
leaves the motion unchanged, so at least one of them must be known.
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
    """Verdict on the free parameters.

    Attributes
    ----------
    identifiable : bool
    singular_values : list of float
        Relative singular values (largest = 1).
    warnings : list of str
        One message per unidentifiable or weak combination, naming the parameters.
    null_directions : list of dict
        ``parameter -> component`` of each unidentifiable direction in log space.
    """

    identifiable: bool
    singular_values: list[float]
    warnings: list[str] = field(default_factory=list)
    null_directions: list[dict[str, float]] = field(default_factory=list)


def _describe(names: list[str], v: FloatArray) -> tuple[str, dict[str, float]]:
    v = v / np.max(np.abs(v))
    if v[np.argmax(np.abs(v))] < 0:
        v = -v
    involved = [(n, float(c)) for n, c in zip(names, v) if abs(c) > 0.1]
    comps = {n: round(c, 3) for n, c in involved}
    same = all(abs(c - 1.0) < 0.1 for _, c in involved)
    plist = ", ".join(n for n, _ in involved)
    if same and len(involved) > 1:
        text = (f"{plist} can all be scaled by one common factor without changing the response "
                f"(only their ratios are identifiable)")
    else:
        combo = " + ".join(f"{c:+.2f}*log({n})" for n, c in involved)
        text = f"the combination {combo} does not change the response"
    return text, comps


def assess(J: FloatArray, names: list[str], kinds: dict[str, str]) -> Identifiability:
    """Judge identifiability from the log-parameter Jacobian ``J`` (rows: residuals).

    Parameters
    ----------
    J : ndarray, shape (M, n_free)
        Sensitivity of the (weighted) residuals to log-parameters.
    names : list of str
        Free parameter names (columns of ``J``).
    kinds : dict
        ``name -> kind`` (mass, inertia, ...) to suggest which parameter to fix.
    """
    if J.size == 0 or len(names) == 0:
        return Identifiability(True, [])
    if not np.all(np.isfinite(J)):
        return Identifiability(False, [], ["sensitivity matrix is not finite at the optimum; "
                                           "the fit did not reach a valid model"])
    _, s, Vt = np.linalg.svd(J, full_matrices=False)
    if s[0] == 0:
        return Identifiability(False, [0.0] * len(names),
                               ["the measured channels do not depend on any free parameter"])
    rel = s / s[0]
    out = Identifiability(True, [float(x) for x in rel])
    for i, r in enumerate(rel):
        if r < WEAK_TOL:
            text, comps = _describe(names, Vt[i])
            masses = [n for n in comps if kinds.get(n) in ("mass", "inertia")]
            fix = masses[0] if masses else next(iter(comps))
            if r < RANK_TOL:
                out.identifiable = False
                out.null_directions.append(comps)
                out.warnings.append(f"unidentifiable: {text}; fix one of them "
                                    f"(e.g. --fix {fix}=VALUE) to make the rest identifiable")
            else:
                out.warnings.append(f"poorly identifiable (relative singular value {r:.1e}): "
                                    f"{text} is only weakly determined by this data")
    return out
