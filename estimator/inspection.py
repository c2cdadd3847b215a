"""Virtual damper test: what an inspection-station shaker would report for a quarter car.

The wheel stands on a plate moving ``r(t) = A sin(2 pi f t)`` (``A = 3 mm``, 25 Hz down
to 2 Hz) and the tyre contact force is measured. With ``s = j 2 pi f`` and the model's
matrices, ``(s^2 M + s C + K) Q = (Fk + s Fc) R``, the dynamic contact force is
``F = (kt + s ct) S`` with the tyre's compression ``S = g . Q + gr R``, and the static
load ``Fs = (m1 + m2) g``. Any model with two coordinates, one road and one tyre site
is a quarter car here (:func:`quarter_car_problem`).

EUSAMA road holding
    ``RH = min_f (Fs - A |F(f)/R|) / Fs x 100 %``, clipped to [0, 100] %; bands 0-20 %
    poor, 21-40 % sufficient, > 40 % good. Found on nested log grids and a parabola's
    vertex (:func:`_grid_min`).
EGEA phase shift
    ``phi(f) = arg(F(f) / R)`` in degrees, continuous and 180 deg in the static limit;
    ``phi_min`` is its minimum between the body and wheel natural frequencies, and the
    criterion is ``phi_min >= 35 deg``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from suspid.models.modes import modes
from suspid.errors import UsageError
from suspid.models import get_model
from suspid.models.base import GRAVITY, FloatArray, Site, SuspensionModel

G = 9.80665
PLATE_AMPLITUDE = 0.003
SWEEP_HZ = (2.0, 25.0)
EGEA_CRITERION_DEG = 35.0
N_GRID = 200


def quarter_car_problem(model: SuspensionModel, p: Mapping[str, float] | None = None) -> str | None:
    """What keeps ``model`` from the virtual damper test at ``p`` (SI; default its defaults):
    one sentence naming what it lacks (two coordinates, one road, one tyre site with a
    spring and a static load), or ``None`` when it qualifies.
    """
    need = "the virtual damper test needs a quarter car (two coordinates, one road, one tyre)"
    if len(model.coords) != 2:
        return (f"{need}: model {model.name} has {len(model.coords)} coordinates "
                f"({', '.join(model.coords)}), expected 2")
    if len(model.roads) != 1:
        return (f"{need}: model {model.name} has {len(model.roads)} roads "
                f"({', '.join(model.roads) or 'none'}), expected 1")
    tyres = model.tyre_sites(model.defaults() if p is None else p)
    if len(tyres) != 1:
        return f"{need}: model {model.name} has {len(tyres)} tyre sites, expected 1"
    if tyres[0].k_name is None:
        return f"{need}: the tyre site of model {model.name} names no tyre spring (k_name)"
    if not tyres[0].load > 0.0:
        return (f"{need}: the tyre site of model {model.name} carries no static load "
                f"(load = {tyres[0].load} N)")
    return None


def tyre_site(model: SuspensionModel, p: Mapping[str, float]) -> Site:
    """The one tyre of a quarter car at parameters ``p`` (SI); :class:`UsageError` naming
    what the model lacks when it is none (:func:`quarter_car_problem`).
    """
    why = quarter_car_problem(model, p)
    if why is not None:
        raise UsageError(why)
    return model.tyre_sites(p)[0]


def response_function(model: SuspensionModel, p: Mapping[str, float]
                      ) -> Callable[[FloatArray], np.ndarray]:
    """``H(f) = F(f) / R`` (Hz -> complex N/m) of a quarter car (:func:`tyre_site`) at
    parameters ``p`` (SI), coefficients precomputed; the 2x2 system is solved by Cramer's
    rule, vectorised over the frequencies.
    """
    site = tyre_site(model, p)
    M, C, K, Fk, Fc = model.matrices(p)
    m11, m12, m21, m22 = (float(v) for v in M.ravel())
    c11, c12, c21, c22 = (float(v) for v in C.ravel())
    k11, k12, k21, k22 = (float(v) for v in K.ravel())
    fk1, fk2 = float(Fk[0, 0]), float(Fk[1, 0])
    fc1, fc2 = float(Fc[0, 0]), float(Fc[1, 0])
    kt = float(p[site.k_name]) if site.k_name is not None else 0.0
    ct = float(p[site.c_name]) if site.c_name is not None else 0.0
    g1, g2 = (float(v) for v in site.g)
    gr = float(site.gr[0])
    sym = (m12, c12, k12) == (m21, c21, k21)
    two_pi = 2.0 * math.pi

    def H(f: FloatArray) -> np.ndarray:
        w = two_pi * np.asarray(f, dtype=float)
        s = 1j * w
        w2 = w * w
        z11 = (k11 - m11 * w2) + c11 * s
        z22 = (k22 - m22 * w2) + c22 * s
        z12 = (k12 - m12 * w2) + c12 * s
        z21 = z12 if sym else (k21 - m21 * w2) + c21 * s
        b1 = fk1 + fc1 * s if (fk1 != 0.0 or fc1 != 0.0) else None
        b2 = fk2 + fc2 * s
        det = z11 * z22 - z12 * z21
        # compression per unit plate motion: only the terms the tyre's geometry has
        comp: Any = gr
        if g2 != 0.0:
            num2 = z11 * b2
            if b1 is not None:
                num2 -= z21 * b1
            comp = comp + g2 * (num2 / det)
        if g1 != 0.0:
            num1 = -z12 * b2
            if b1 is not None:
                num1 += z22 * b1
            comp = comp + g1 * (num1 / det)
        return np.asarray((kt + ct * s) * comp)

    return H


def eusama_band(rh: float) -> str:
    """EUSAMA band of a road-holding value (%)."""
    if rh > 40.0:
        return "good"
    if rh > 20.0:
        return "sufficient"
    return "poor"


@dataclass
class Inspection:
    """Virtual shaker result: EUSAMA road holding (%), its band and the frequency of the
    minimum wheel load (Hz); the EGEA minimum phase shift (deg), its frequency (Hz) and
    whether it passes (``phi_min >= 35 deg``); the body and wheel natural frequencies (Hz);
    the tyre site's static load at ``g =`` :data:`G` (N).
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


_UNIT: dict[int, FloatArray] = {}


def _log_grid(a: float, b: float, n: int) -> FloatArray:
    """``n`` logarithmically spaced points from ``a`` to ``b`` (both included)."""
    u = _UNIT.get(n)
    if u is None:
        u = _UNIT[n] = np.linspace(0.0, 1.0, n)
    x = a * np.exp(u * math.log(b / a))
    x[-1] = b
    return x


def _phase_deg(H: Callable[[FloatArray], np.ndarray], f: FloatArray) -> FloatArray:
    """Continuous phase of ``F/R`` (deg) at ``f``, anchored at 180 deg in the static limit."""
    grid = np.concatenate([[1e-3], np.asarray(f, dtype=float)])
    ph = np.angle(H(grid))
    # unwrap (as numpy.unwrap), then anchor the static limit at pi
    ph[1:] -= (2 * np.pi) * np.cumsum(np.round(np.diff(ph) / (2 * np.pi)))
    ph -= 2 * np.pi * round((float(ph[0]) - np.pi) / (2 * np.pi))
    return np.degrees(ph[1:])


def _vertex(x: FloatArray, v: FloatArray, i: int) -> tuple[float, float]:
    """Refine the grid minimum ``(x[i], v[i])`` by the parabola through its neighbours (in ``log x``)."""
    if i <= 0 or i >= x.size - 1:
        return float(x[i]), float(v[i])
    vm, v0, vp = float(v[i - 1]), float(v[i]), float(v[i + 1])
    curv = vm - 2.0 * v0 + vp
    if not curv > 0.0:
        return float(x[i]), v0
    d = 0.5 * (vm - vp) / curv  # vertex offset in grid steps, |d| <= 1/2 for a grid minimum
    if not abs(d) <= 1.0:
        return float(x[i]), v0
    vv = v0 - 0.25 * (vm - vp) * d
    step = math.log(float(x[i + 1]) / float(x[i]))
    return float(x[i]) * math.exp(d * step), min(vv, v0)


def _grid_min(fun: Callable[[FloatArray], FloatArray], lo: float, hi: float, n0: int,
              levels: int = 2) -> tuple[float, float]:
    """Minimum of a smooth vectorised function on ``[lo, hi]`` by nested log grids: an
    ``n0``-point grid, then 65 points between the previous minimum's neighbours per level,
    and the parabola's vertex (:func:`_vertex`).
    """
    a, b = lo, hi
    m = n0
    x: FloatArray = np.empty(0)
    v: FloatArray = np.empty(0)
    i = 0
    for _ in range(levels):
        x = _log_grid(a, b, m)
        v = fun(x)
        i = int(np.argmin(v))
        a, b = float(x[max(i - 1, 0)]), float(x[min(i + 1, m - 1)])
        m = 65
        if b <= a:
            break
    return _vertex(x, v, i)


def inspect(params: Mapping[str, float], model: SuspensionModel | None = None) -> Inspection:
    """EUSAMA road holding and EGEA phase shift of a quarter car (:func:`quarter_car_problem`,
    default ``quarter2``) at ``params`` (SI), swept over :data:`SWEEP_HZ` at
    :data:`PLATE_AMPLITUDE` from a first log grid of :data:`N_GRID` points.
    """
    model = model or get_model("quarter2")
    fs = float(tyre_site(model, params).load) * (G / GRAVITY)
    f_lo, f_hi = SWEEP_HZ
    a2 = (PLATE_AMPLITUDE / fs) ** 2

    H = response_function(model, params)

    def neg_force2(f: FloatArray) -> FloatArray:
        # the lowest wheel load is at the largest |F/R|; compare squares (no square root)
        h = H(f)
        return -(h.real * h.real + h.imag * h.imag)

    f_min, v = _grid_min(neg_force2, f_lo, f_hi, N_GRID)
    rh = 1.0 - math.sqrt(-v * a2)
    rh_pct = float(min(100.0, max(0.0, 100.0 * rh)))
    ms = modes(model, params)
    f_body, f_wheel = ms[0].f_n, ms[-1].f_n
    a, b = max(f_lo, f_body), min(f_hi, f_wheel)
    if b <= a:
        a, b = f_lo, f_hi
    # the phase anchored once on a grid from the static limit; nested levels re-anchor on it
    grid = _log_grid(a, b, N_GRID)
    anchor = _phase_deg(H, grid)

    def phase(f: FloatArray) -> FloatArray:
        v = np.degrees(np.angle(H(f)))
        ref = float(np.interp(f[0], grid, anchor))
        return v + 360.0 * np.round((ref - v) / 360.0)

    i = int(np.argmin(anchor))
    f_phi, phi = float(grid[i]), float(anchor[i])
    lo_b, hi_b = float(grid[max(i - 1, 0)]), float(grid[min(i + 1, N_GRID - 1)])
    if hi_b > lo_b:
        f2, phi2 = _grid_min(phase, lo_b, hi_b, 65, levels=1)
        if phi2 < phi:
            f_phi, phi = f2, phi2
    return Inspection(rh_pct, eusama_band(rh_pct), f_min, phi, f_phi, phi >= EGEA_CRITERION_DEG,
                      float(f_body), float(f_wheel), float(fs))
