"""The vibration modes of a linear model: natural frequency, damping ratio, period, decay.

``modes(model, params)`` takes the eigenvalues ``lambda_i`` of the model's state matrix
``A`` (:meth:`~suspid.models.base.SuspensionModel.state_space`): natural frequency
``w_i = |lambda_i|``, damping ratio ``zeta_i = -Re(lambda_i) / |lambda_i|``, damped period
``T_i = 2 pi / Im(lambda_i)``, decay time ``tau_i = 1 / (zeta_i w_i)``. The monitor's window
defaults and the virtual damper test read them.
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
    """One vibration mode (complex-conjugate pair or real pole) of a linear model.

    Attributes
    ----------
    f_n : float
        Natural frequency (Hz).
    zeta : float
        Damping ratio (dimensionless).
    period : float
        Damped period (s); ``inf`` for a real (overdamped) pole.
    tau : float
        Decay time constant ``1 / (zeta w_n)`` (s).
    """

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
