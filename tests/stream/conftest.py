"""Shared streams of the streaming-estimator tests (generated once per session)."""
from __future__ import annotations

import numpy as np
import pytest

from estimator.stream.wear_streams import Stream, damper_wear
from suspid.excitation import iso8608_profile, time_grid
from suspid.models import get_model
from suspid.simulate import outputs, road_matrix, simulate_states

#: the must-show stream: c1 falls linearly from 1500 to 750 N s/m between 10 s and 100 s,
#: crossing 70 % of nominal (1050 N s/m) at 64 s -- the damper-wear scenario, shortened
WEAR = dict(duration=100.0, fs=500.0, wear_start=10.0, c_end_fraction=0.5, seed=3)


@pytest.fixture(scope="session")
def wear_stream() -> Stream:
    return damper_wear(get_model("quarter2"), **WEAR)


@pytest.fixture(scope="session")
def quarter2():
    return get_model("quarter2")


def half4_wear(duration: float = 80.0, fs: float = 250.0, wear_start: float = 20.0,
               wear_end: float = 70.0, c_end_fraction: float = 0.5, noise: float = 0.01,
               seed: int = 4) -> Stream:
    """Half car on an ISO 8608 class C road at 50 km/h (rear wheel on the front's road,
    delayed by the wheelbase) while the front damper c1 loses damping linearly; white noise
    of ``noise`` x each channel's RMS on x, delta, x1, x2 and both roads."""
    m = get_model("half4")
    p0 = m.defaults()
    t = time_grid(duration, fs)
    wb = p0["a1"] + p0["a2"]
    r1, r1d = iso8608_profile(t, "C", 50.0, seed, lag=0.0, lead=wb + 1.0)
    r2, r2d = iso8608_profile(t, "C", 50.0, seed, lag=wb, lead=wb + 1.0)
    road = {"r1": r1, "r1_dot": r1d, "r2": r2, "r2_dot": r2d}
    U = road_matrix(m, t, road)
    c_true = p0["c1"] * np.interp(t, [wear_start, wear_end], [1.0, c_end_fraction])
    X = np.empty((t.size, m.n_states))
    x = np.zeros(m.n_states)
    step = max(1, int(round(0.05 * fs)))
    for i0 in range(0, t.size - 1, step):
        i1 = min(i0 + step, t.size - 1)
        p = dict(p0, c1=float(c_true[(i0 + i1) // 2]))
        seg = slice(i0, i1 + 1)
        X[seg] = simulate_states(m, p, t[seg], U[seg], x)
        x = X[i1]
    out = outputs(m, p0, X, U)
    rng = np.random.default_rng(seed + 1)
    data = {}
    for c in ("x", "delta", "x1", "x2", "r1", "r2"):
        y = np.asarray(road[c] if c in road else out[c], dtype=float)
        data[c] = y + rng.normal(0.0, noise * float(np.std(y)), t.size)
    truth = {k: np.full(t.size, v) for k, v in p0.items()}
    truth["c1"] = c_true
    return Stream(t, data, truth, dict(p0))


@pytest.fixture(scope="session")
def half4_wear_stream() -> Stream:
    return half4_wear()


#: the seed's Table 1 quarter car (a stiff suspension)
TABLE1 = {"m1": 275.0, "c1": 1120.0, "k1": 150000.0, "m2": 27.0, "c2": 3100.0, "k2": 310000.0}


@pytest.fixture(scope="session")
def stiff_wear_stream() -> Stream:
    """Table 1 quarter car, random road, 2 % noise on every channel (of its RMS), c1 falling
    linearly from 1120 to 560 N s/m between 30 and 120 s: crosses 70 % of nominal at 84 s."""
    m = get_model("quarter2")
    kw = dict(duration=150.0, fs=500.0, params=TABLE1, c_end_fraction=0.5, wear_start=30.0,
              wear_end=120.0, seed=3)
    clean = damper_wear(m, noise={c: 0.0 for c in ("x1", "x2", "x1_ddot", "r", "r_dot")},
                        quantize=False, **kw)
    noise = {c: 0.02 * float(np.std(v)) for c, v in clean.data.items()}
    return damper_wear(m, noise=noise, **kw)
