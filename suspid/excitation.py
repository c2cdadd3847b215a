"""Excitations for the suspension models: ``initial`` (no road; the model's initial state),
``curb`` (a half-cosine step of height ``h``), ``bump`` (a raised cosine of length ``l``
crossed at ``v`` km/h) and ``iso8608`` (a random road of ISO 8608 class A-H: displacement PSD
``Gd(n0) (n / n0)^-2``, ``n0 = 0.1 cycles/m``, ``Gd(n0)`` 16e-6 m^3 for A and 4x per class,
over 0.011-2.83 cycles/m). A road running ``L`` m behind the first axle on its track sees the
track delayed by ``L / v``; the ISO road draws one profile per track (seed ``seed + 7919 j``).
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
    """Synthesise an ISO 8608 road of at least ``length`` (m): ``(s, z)`` in m."""
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
    z = np.asarray(np.fft.irfft(spec, n_pts), dtype=np.float64)
    return np.arange(n_pts, dtype=np.float64) * ds, z - z[0]


def iso8608_profile(t: FloatArray, road_class: str = "C", v_kmh: float = 50.0, seed: int = 0,
                    lag: float = 0.0, lead: float = 0.0) -> tuple[FloatArray, FloatArray]:
    """ISO 8608 road seen at speed ``v_kmh`` by a wheel ``lag`` m behind the first: ``r``, ``r'``
    (``lead``, m: road synthesised before the first wheel, >= the largest lag)."""
    v = v_kmh / 3.6
    if v <= 0:
        raise UsageError(f"road speed must be > 0 km/h, got {v_kmh}")
    s_grid, z = iso8608_road(v * (t[-1] - t[0]) + lead + 0.1, road_class, seed)
    s = v * (t - t[0]) + lead - lag
    r = np.interp(s, s_grid, z)
    rd = np.interp(s, s_grid, np.gradient(z, s_grid)) * v
    return r, rd


def time_grid(duration: float, fs: float) -> FloatArray:
    """Sample times ``0, 1/fs, ..., duration`` (s); UsageError unless finite, > 0 and at most
    :data:`MAX_SAMPLES` samples."""
    if not (0 < duration < math.inf and 0 < fs < math.inf):
        raise UsageError(f"duration and sample rate must be finite and > 0, got {duration} s, {fs} Hz")
    if duration * fs > MAX_SAMPLES:
        raise UsageError(f"duration x sample rate = {duration * fs:.3g} samples; expected at most "
                         f"{MAX_SAMPLES:.0e} ({duration} s at {fs} Hz)")
    return np.arange(int(round(duration * fs)) + 1) / fs


def measured_road(model: SuspensionModel, t: FloatArray, road: Mapping[str, FloatArray],
                  params: Mapping[str, float] | None = None, v_kmh: float = 20.0,
                  source: str = "road") -> dict[str, FloatArray]:
    """A measured road as the model's input.

    A missing road running behind a given one on the same track is that road delayed by the
    distance over the speed (``half4``: ``r2(t) = r1(t - (a1 + a2) / v)``); any other missing
    road is an InputError naming it.
    """
    out = {k: np.asarray(v, dtype=float) for k, v in road.items()}
    p = dict(model.defaults(), **(params or {}))
    where = list(zip(model.road_tracks(), model.road_lags(p)))
    for i, name in enumerate(model.roads):
        if name in out:
            continue
        track, lag = where[i]
        given = [(where[j][1], rn) for j, rn in enumerate(model.roads)
                 if rn in road and where[j][0] == track and where[j][1] < lag]
        if not given:
            raise InputError(f"{source}: no road column {name!r} for model {model.name}; expected "
                             f"{', '.join(model.roads)} (and optionally their _dot)")
        if not 0 < v_kmh < math.inf:
            raise UsageError(f"speed must be finite and > 0 km/h to delay the road {name}, "
                             f"got {v_kmh}")
        lag0, first = max(given)
        delay = (lag - lag0) / (v_kmh / 3.6)
        out[name] = np.interp(t - delay, t, out[first])
        if f"{first}_dot" in out:
            out[f"{name}_dot"] = np.interp(t - delay, t, out[f"{first}_dot"], left=0.0)
    return out


def make_scenario(model: SuspensionModel, name: str, duration: float = 5.0, fs: float = 1000.0,
                  params: Mapping[str, float] | None = None, h: float = 0.1, l: float = 3.0,
                  v_kmh: float = 20.0, t0: float = 0.5, rise: float = 0.02,
                  road_class: str = "C", seed: int = 0,
                  x0: FloatArray | None = None) -> tuple[FloatArray, dict[str, FloatArray], FloatArray]:
    """Build the time grid, road dict and initial state of a named scenario.

    ``duration`` in s, ``fs`` in Hz, ``params`` (SI) for the road lags; ``h``, ``l`` (m),
    ``v_kmh``, ``t0``, ``rise`` (s), ``road_class``, ``seed`` shape the road (module docstring).
    ``x0`` defaults to the model's ``initial_state()`` for ``initial``, rest otherwise. Returns
    the times (s), ``{road: r, road_dot: r'}`` (m, m/s; empty for ``initial``) and ``x0``.
    """
    t = time_grid(duration, fs)
    p = dict(model.defaults(), **(params or {}))
    road: dict[str, FloatArray] = {}
    if name == "initial":
        return t, road, np.asarray(model.initial_state() if x0 is None else x0, dtype=float)
    if name not in SCENARIOS:
        raise UsageError(f"unknown scenario {name!r}; expected one of {', '.join(SCENARIOS)}")
    v = v_kmh / 3.6
    where = list(zip(model.road_tracks(), model.road_lags(p)))
    lead = max((lag for _, lag in where), default=0.0)
    if lead > 0 and not 0 < v < math.inf:
        raise UsageError(f"speed must be finite and > 0 km/h to delay the rear roads, got {v_kmh}")
    for i, rn in enumerate(model.roads):
        track, lag = where[i]
        shift = lag / v if lag else 0.0
        if name == "curb":
            r, rd = curb_profile(t, h, t0 + shift, rise)
        elif name == "bump":
            r, rd = bump_profile(t, h, l, v_kmh, t0 + shift)
        else:
            r, rd = iso8608_profile(t, road_class, v_kmh, seed + 7919 * track, lag=lag, lead=lead)
        road[rn] = r
        road[f"{rn}_dot"] = rd
    return t, road, np.zeros(model.n_states) if x0 is None else np.asarray(x0, dtype=float)
