"""Excitations (road inputs and initial states) for the suspension models.

Shapes (all documented in README and docs):

* ``initial``: no road input; the body (and optionally the wheels) start away from
  equilibrium. Default for ``quarter2`` is the seed's Table 2 (x01 = 0.20 m, v01 = 0.50 m/s,
  x02 = 0.10 m, v02 = 0.05 m/s); for ``half4`` the seed's §6.1 body state (x = 0.05 m,
  x' = 0.05 m/s, delta = 0.05 rad, delta' = 0.05 rad/s).
* ``curb``: a step of height ``h`` (m) at ``t0`` (s) with a half-cosine rise of duration
  ``rise`` (s, default 0.02 s), so ``r' = h pi / (2 rise) sin(...)`` stays finite.
* ``bump``: a speed bump of height ``h`` (m) and length ``l`` (m) crossed at speed ``v``
  (km/h) starting at ``t0``; the profile over the bump's length is the raised cosine
  ``r(s) = h/2 (1 - cos(2 pi s / l))`` for ``0 <= s <= l`` (seed: 0.1 m, 3 m, 20 km/h).
* ``iso8608``: a random road of ISO 8608 class A-H at speed ``v`` (km/h): displacement PSD
  ``Gd(n) = Gd(n0) (n / n0)^-2`` with ``n0 = 0.1 cycles/m`` and ``Gd(n0)`` the class's
  geometric mean (A: 16e-6 m^3, each class 4x the previous), synthesised by inverse FFT
  with random phases over 0.011-2.83 cycles/m.
* measured roads come from the measurement CSV.

For ``half4`` the rear wheel sees the front road delayed by the wheelbase over the speed,
``r2(t) = r1(t - (a1 + a2) / v)``.
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from suspid.errors import InputError, UsageError
from suspid.models.base import FloatArray, SuspensionModel

SCENARIOS = ("initial", "curb", "bump", "iso8608")
#: longest record make_scenario builds (samples; 11 h at 500 Hz, 160 MB per array)
MAX_SAMPLES = 20_000_000
ISO8608_CLASSES = {c: 16e-6 * 4.0 ** i for i, c in enumerate("ABCDEFGH")}


def curb_profile(t: FloatArray, h: float = 0.1, t0: float = 0.5, rise: float = 0.02
                 ) -> tuple[FloatArray, FloatArray]:
    """Curb (rounded step) road ``r`` (m) and ``r'`` (m/s) at times ``t`` (s)."""
    if rise <= 0:
        raise UsageError(f"curb rise must be > 0 s, got {rise}")
    s = np.clip((t - t0) / rise, 0.0, 1.0)
    r = h * 0.5 * (1 - np.cos(np.pi * s))
    rd = np.where((s > 0) & (s < 1), h * np.pi / (2 * rise) * np.sin(np.pi * s), 0.0)
    return r, rd


def bump_profile(t: FloatArray, h: float = 0.1, l: float = 3.0, v_kmh: float = 20.0,
                 t0: float = 0.5) -> tuple[FloatArray, FloatArray]:
    """Raised-cosine speed bump: road ``r`` (m) and ``r'`` (m/s) at times ``t`` (s)."""
    if l <= 0 or v_kmh <= 0:
        raise UsageError(f"bump length and speed must be > 0, got l={l} m, v={v_kmh} km/h")
    v = v_kmh / 3.6
    s = v * (t - t0)
    inside = (s >= 0) & (s <= l)
    r = np.where(inside, h / 2 * (1 - np.cos(2 * np.pi * s / l)), 0.0)
    rd = np.where(inside, h / 2 * (2 * np.pi * v / l) * np.sin(2 * np.pi * s / l), 0.0)
    return r, rd


def iso8608_road(length: float, road_class: str = "C", seed: int = 0,
                 ds: float = 0.02) -> tuple[FloatArray, FloatArray]:
    """Synthesise an ISO 8608 road of at least ``length`` (m): ``(s, z)`` in m.

    Cosine amplitudes from the one-sided displacement PSD on the FFT grid, random phases.
    """
    cls = road_class.upper()
    if cls not in ISO8608_CLASSES:
        raise UsageError(f"unknown ISO 8608 road class {road_class!r}; expected one of A-H")
    n_pts = int(2 ** np.ceil(np.log2(max(length / ds + 2, 256))))
    n = np.fft.rfftfreq(n_pts, ds)
    G = np.zeros_like(n)
    band = (n >= 0.011) & (n <= 2.83)
    G[band] = ISO8608_CLASSES[cls] * (n[band] / 0.1) ** -2
    dn = n[1] - n[0]
    rng = np.random.default_rng(seed)
    amp = np.sqrt(2 * G * dn)
    spec = amp * np.exp(1j * rng.uniform(0, 2 * np.pi, n.size)) * n_pts / 2
    z = np.fft.irfft(spec, n_pts)
    return np.arange(n_pts) * ds, z - z[0]


def iso8608_profile(t: FloatArray, road_class: str = "C", v_kmh: float = 50.0, seed: int = 0,
                    lag: float = 0.0, lead: float = 0.0) -> tuple[FloatArray, FloatArray]:
    """ISO 8608 road seen at speed ``v_kmh`` by a wheel ``lag`` m behind the first: ``r``, ``r'``.

    ``lead`` (m) is the road length synthesised before the first wheel's start (>= the
    largest lag used with the same seed, so all wheels share one road).
    """
    v = v_kmh / 3.6
    if v <= 0:
        raise UsageError(f"road speed must be > 0 km/h, got {v_kmh}")
    s_grid, z = iso8608_road(v * (t[-1] - t[0]) + lead + 0.1, road_class, seed)
    s = v * (t - t[0]) + lead - lag
    r = np.interp(s, s_grid, z)
    rd = np.interp(s, s_grid, np.gradient(z, s_grid)) * v
    return r, rd


def time_grid(duration: float, fs: float) -> FloatArray:
    """Sample times ``0, 1/fs, ..., duration`` (s).

    Raises
    ------
    UsageError
        A duration or rate that is not finite and > 0, or more than :data:`MAX_SAMPLES`
        samples.
    """
    if not (0 < duration < math.inf and 0 < fs < math.inf):
        raise UsageError(f"duration and sample rate must be finite and > 0, got {duration} s, {fs} Hz")
    if duration * fs > MAX_SAMPLES:
        raise UsageError(f"duration x sample rate = {duration * fs:.3g} samples; expected at most "
                         f"{MAX_SAMPLES:.0e} ({duration} s at {fs} Hz)")
    return np.arange(int(round(duration * fs)) + 1) / fs


def measured_road(model: SuspensionModel, t: FloatArray, road: Mapping[str, FloatArray],
                  params: Mapping[str, float] | None = None, v_kmh: float = 20.0,
                  source: str = "road") -> dict[str, FloatArray]:
    """A measured road (e.g. a profilometer or a rig actuator record) as the model's input.

    Every road of the model must be given, except that ``half4`` with only ``r1`` gets the
    rear road ``r2(t) = r1(t - (a1 + a2) / v)`` (held at ``r1``'s first value before the
    record starts). A road without its ``_dot`` is differentiated numerically later
    (:func:`suspid.simulate.road_matrix`).

    Raises
    ------
    InputError
        A road of the model is missing (named).
    """
    out = {k: np.asarray(v, dtype=float) for k, v in road.items()}
    first = model.roads[0]
    if first not in out:
        raise InputError(f"{source}: no road column {first!r} for model {model.name}; expected "
                         f"{', '.join(model.roads)} (and optionally their _dot)")
    if len(model.roads) == 2 and model.roads[1] not in out:
        if not 0 < v_kmh < math.inf:
            raise UsageError(f"speed must be finite and > 0 km/h to delay the rear road, got {v_kmh}")
        p = dict(model.defaults(), **(params or {}))
        delay = (p["a1"] + p["a2"]) / (v_kmh / 3.6)
        rear = model.roads[1]
        out[rear] = np.interp(t - delay, t, out[first])
        if f"{first}_dot" in out:
            out[f"{rear}_dot"] = np.interp(t - delay, t, out[f"{first}_dot"], left=0.0)
    return out


def make_scenario(model: SuspensionModel, name: str, duration: float = 5.0, fs: float = 1000.0,
                  params: Mapping[str, float] | None = None, h: float = 0.1, l: float = 3.0,
                  v_kmh: float = 20.0, t0: float = 0.5, rise: float = 0.02,
                  road_class: str = "C", seed: int = 0,
                  x0: FloatArray | None = None) -> tuple[FloatArray, dict[str, FloatArray], FloatArray]:
    """Build the time grid, road dict and initial state of a named scenario.

    Parameters
    ----------
    model : SuspensionModel
    name : {"initial", "curb", "bump", "iso8608"}
    duration : float
        Record length (s).
    fs : float
        Sample rate (Hz).
    params : mapping, optional
        Model parameters (``half4`` uses ``a1 + a2`` as the wheelbase for the rear delay).
    h, l, v_kmh, t0, rise, road_class, seed
        Shape parameters (see the module docstring); ``v_kmh`` is also the ISO road speed.
    x0 : ndarray, optional
        Initial state; default the seed's initial states for ``initial``, rest otherwise.

    Returns
    -------
    t : ndarray
        Times (s).
    road : dict
        ``{road: r, road_dot: r'}`` (m, m/s); empty for ``initial``.
    x0 : ndarray
        Initial state ``[q, q']``.
    """
    t = time_grid(duration, fs)
    p = dict(model.defaults(), **(params or {}))
    n = model.n_states
    road: dict[str, FloatArray] = {}
    if name == "initial":
        if x0 is None:
            x0 = np.zeros(n)
            if model.name == "quarter1":
                x0[:] = [0.20, 0.50]
            elif model.name == "quarter2":
                x0[:] = [0.20, 0.10, 0.50, 0.05]
            else:
                x0[[0, 1, 4, 5]] = [0.05, 0.05, 0.05, 0.05]
        return t, road, np.asarray(x0, dtype=float)
    if name not in SCENARIOS:
        raise UsageError(f"unknown scenario {name!r}; expected one of {', '.join(SCENARIOS)}")
    delay = 0.0
    if len(model.roads) == 2:
        delay = (p["a1"] + p["a2"]) / (v_kmh / 3.6)
    for i, rn in enumerate(model.roads):
        shift = delay * i
        if name == "curb":
            r, rd = curb_profile(t, h, t0 + shift, rise)
        elif name == "bump":
            r, rd = bump_profile(t, h, l, v_kmh, t0 + shift)
        else:
            wheelbase = delay * v_kmh / 3.6
            r, rd = iso8608_profile(t, road_class, v_kmh, seed, lag=wheelbase * i, lead=wheelbase)
        road[rn] = r
        road[f"{rn}_dot"] = rd
    return t, road, np.zeros(n) if x0 is None else np.asarray(x0, dtype=float)
