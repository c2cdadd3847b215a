"""The vibration modes of a linear model from the eigenvalues ``lambda`` of its state matrix:
``w = |lambda|``, ``zeta = -Re(lambda) / w``, damped period ``2 pi / Im(lambda)``, decay
time ``1 / (zeta w)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np
from scipy.linalg.lapack import dgeev as _dgeev

from suspid.models.base import SuspensionModel


@dataclass(frozen=True)
class Mode:
    """One mode (conjugate pair or real pole): natural frequency ``f_n`` (Hz), damping ratio
    ``zeta``, damped period (s; ``inf`` for a real pole) and decay time ``tau`` (s)."""

    f_n: float
    zeta: float
    period: float
    tau: float


def modes(model: SuspensionModel, params: Mapping[str, float]) -> list[Mode]:
    """Modes of ``model`` at ``params``, slowest first (one per conjugate pair)."""
    A, _ = model.state_space(params)
    # LAPACK dgeev without eigenvectors (numpy's eigvals does the same, with more overhead)
    wr, wi, _, _, info = _dgeev(A, compute_vl=0, compute_vr=0)
    if info != 0:
        raise np.linalg.LinAlgError(f"eigenvalues of A did not converge (dgeev info {info})")
    out = []
    for l in (complex(a, b) for a, b in zip(wr.tolist(), wi.tolist())):
        if l.imag < -1e-12:
            continue
        wn = abs(l)
        if wn == 0:
            continue
        zeta = -l.real / wn
        period = 2 * math.pi / l.imag if l.imag > 1e-12 else math.inf
        tau = 1.0 / (zeta * wn) if zeta > 0 else math.inf
        out.append(Mode(float(wn / (2 * math.pi)), float(zeta), float(period), float(tau)))
    return sorted(out, key=lambda m: m.f_n)
