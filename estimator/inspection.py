"""Virtual damper test: what an inspection-station shaker would report for a quarter car.

Both tests put the wheel on a plate that moves sinusoidally, ``r(t) = A sin(2 pi f t)`` with
``A = 3 mm``, swept from 25 Hz down to 2 Hz, and measure the vertical tyre contact force.
For identified quarter-car parameters the steady-state response at every frequency is exact
(the sweep is slow enough to be quasi-stationary). With ``s = j 2 pi f`` and the model's
matrices ``M, C, K, Fk, Fc`` (:meth:`~suspid.models.base.SuspensionModel.matrices`)::

    (s^2 M + s C + K) Q(s) = (Fk + s Fc) R          (Q = [X1, X2], body and wheel)
    F(s) = (k2 + s c2) (R - X2(s))                   (dynamic contact force, compression +)
    Fs   = (m1 + m2) g                               (static wheel load, g = 9.80665 m/s^2)

EUSAMA road holding
    ``RH = min over f in [2, 25] Hz of (Fs - A |F(f)/R|) / Fs x 100 %`` — the lowest
    instantaneous wheel load over the sweep relative to the static load, clipped to
    [0, 100] % (0: the tyre lifts off). Bands: 0-20 % poor, 21-40 % sufficient, > 40 % good.
    The minimum is located on nested logarithmic grids (three levels of 400 points, the
    bracket shrinking ~200-fold per level: ~1e-7 relative in frequency).
EGEA phase shift
    ``phi(f) = arg(F(f) / R)`` in degrees, continuous in ``f`` and equal to 180 deg in the
    quasi-static limit (the plate lifting the whole corner pushes hardest at the bottom of
    its stroke). Between the body and the wheel resonance the force is the sum of the body's
    and the wheel's inertial reactions; with a weak damper the body's reaction swings the
    phase down towards 0 deg. ``phi_min`` is the minimum of ``phi`` over the sweep between
    the two resonant (natural) frequencies of the model; the EGEA (SPECSUS2018) criterion is
    ``phi_min >= 35 deg``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from estimator.stream.config import modes
from suspid.errors import UsageError
from suspid.models import get_model
from suspid.models.base import FloatArray, SuspensionModel

G = 9.80665
PLATE_AMPLITUDE = 0.003
SWEEP_HZ = (2.0, 25.0)
EGEA_CRITERION_DEG = 35.0


def contact_force_response(model: SuspensionModel, p: Mapping[str, float], f: FloatArray) -> np.ndarray:
    """Complex ``F(f) / R`` (N/m): dynamic tyre force per metre of plate displacement."""
    if model.name != "quarter2":
        raise UsageError(f"the virtual damper test needs model quarter2, got {model.name}")
    M, C, K, Fk, Fc = model.matrices(p)
    s = 2j * np.pi * np.asarray(f, dtype=float)
    Z = s[:, None, None] ** 2 * M + s[:, None, None] * C + K          # (nf, 2, 2)
    rhs = Fk[None, :, 0] + s[:, None] * Fc[None, :, 0]                 # (nf, 2)
    Q = np.linalg.solve(Z, rhs[:, :, None])[:, :, 0]
    return (p["k2"] + s * p["c2"]) * (1.0 - Q[:, 1])


def eusama_band(rh: float) -> str:
    """EUSAMA band of a road-holding value (%)."""
    if rh > 40.0:
        return "good"
    if rh > 20.0:
        return "sufficient"
    return "poor"


@dataclass
class Inspection:
    """Virtual shaker result.

    Attributes
    ----------
    eusama_pct : float
        EUSAMA road holding (%).
    eusama_band : str
        ``poor`` (0-20 %), ``sufficient`` (21-40 %), ``good`` (> 40 %).
    eusama_f_hz : float
        Frequency of the minimum wheel load (Hz).
    phi_min_deg : float
        EGEA minimum phase shift (deg).
    phi_f_hz : float
        Frequency of ``phi_min`` (Hz).
    egea_pass : bool
        ``phi_min >= 35 deg``.
    f_body_hz, f_wheel_hz : float
        Natural frequencies of the body and wheel modes (Hz).
    static_load_n : float
        ``(m1 + m2) g`` (N).
    """

    eusama_pct: float
    eusama_band: str
    eusama_f_hz: float
    phi_min_deg: float
    phi_f_hz: float
    egea_pass: bool
    f_body_hz: float
    f_wheel_hz: float
    static_load_n: float

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)


def _phase_deg(model: SuspensionModel, p: Mapping[str, float], f: FloatArray) -> FloatArray:
    """Continuous phase of ``F/R`` (deg), anchored at 180 deg in the static limit."""
    grid = np.concatenate([[1e-3], np.asarray(f, dtype=float)])
    ph = np.unwrap(np.angle(contact_force_response(model, p, grid)))
    ph = ph - 2 * np.pi * np.round((ph[0] - np.pi) / (2 * np.pi))
    return np.degrees(ph[1:])


def _grid_min(fun: Callable[[FloatArray], FloatArray], lo: float, hi: float, n: int,
              levels: int = 3) -> tuple[float, float]:
    """Minimum of a smooth vectorised function on ``[lo, hi]`` by nested log grids.

    Level 1 is an ``n``-point logarithmic grid over the whole range; each further level puts
    ``n`` points between the neighbours of the previous minimum, so the bracket shrinks by
    about ``n / 2`` per level (three levels of 400 points: ~1e-7 relative in frequency).
    """
    a, b = lo, hi
    best_x, best_f = lo, math.inf
    for _ in range(levels):
        x = np.geomspace(a, b, n)
        v = fun(x)
        i = int(np.argmin(v))
        if v[i] < best_f:
            best_x, best_f = float(x[i]), float(v[i])
        a, b = float(x[max(i - 1, 0)]), float(x[min(i + 1, n - 1)])
        if b <= a:
            break
    return best_x, best_f


def inspect(params: Mapping[str, float], model: SuspensionModel | None = None,
            amplitude: float = PLATE_AMPLITUDE, sweep: tuple[float, float] = SWEEP_HZ,
            n_grid: int = 400) -> Inspection:
    """EUSAMA road holding and EGEA phase shift of a quarter car.

    Parameters
    ----------
    params : mapping
        Quarter-car parameters ``m1, c1, k1, m2, c2, k2`` (SI).
    model : SuspensionModel, optional
        Default ``quarter2``.
    amplitude : float
        Plate amplitude (m), default 3 mm.
    sweep : (float, float)
        Frequency range of the sweep (Hz), default 2-25 Hz.
    n_grid : int
        Points per level of the nested logarithmic search grids (three levels).

    Returns
    -------
    Inspection
    """
    model = model or get_model("quarter2")
    fs = (params["m1"] + params["m2"]) * G
    f_lo, f_hi = sweep

    def load_ratio(f: FloatArray) -> FloatArray:
        return (fs - amplitude * np.abs(contact_force_response(model, params, f))) / fs

    f_min, rh = _grid_min(load_ratio, f_lo, f_hi, n_grid)
    rh_pct = float(min(100.0, max(0.0, 100.0 * rh)))
    ms = modes(model, params)
    f_body, f_wheel = ms[0].f_n, ms[-1].f_n
    a, b = max(f_lo, f_body), min(f_hi, f_wheel)
    if b <= a:
        a, b = f_lo, f_hi
    # the continuous phase is anchored once on a grid from the static limit; nested levels
    # re-anchor on the previous level's value (the phase is smooth inside a bracket)
    anchor = _phase_deg(model, params, np.geomspace(a, b, n_grid))

    def phase(f: FloatArray) -> FloatArray:
        v = np.degrees(np.angle(contact_force_response(model, params, f)))
        ref = float(np.interp(f[0], np.geomspace(a, b, n_grid), anchor))
        return v + 360.0 * np.round((ref - v) / 360.0)

    f_phi, phi = _grid_min(phase, a, b, n_grid)
    phi = min(phi, float(np.min(anchor)))
    return Inspection(rh_pct, eusama_band(rh_pct), f_min, phi, f_phi, phi >= EGEA_CRITERION_DEG,
                      float(f_body), float(f_wheel), float(fs))
