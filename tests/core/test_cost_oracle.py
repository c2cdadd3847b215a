"""The one output-error cost against an accurate ``solve_ivp`` simulation (DOP853 of the
model's right-hand side, the same first-order-hold road).

Every path of :class:`~estimator.identify.OutputErrorProblem` is checked on data the oracle
simulated from a non-zero initial state: the fast path (a uniform grid, every sample
observed, ``x0`` estimated; with weights, with ride heights, on a record long enough for its
blocked-scan branch) and the general paths (missing samples, a jittered grid). At the true
parameters the cost vanishes and the initial state is recovered; at other parameters the
prediction is the oracle's trajectory from the estimated initial state.
"""
from __future__ import annotations

import numpy as np
import pytest

from estimator.identify import OutputErrorProblem
from estimator.identify.fastpath import MAX_DECAY_EXPONENT
from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement
from suspid.models import get_model
from suspid.simulate import simulate_ode


def _record(name: str, duration: float, fs: float, jitter: bool = False):
    m = get_model(name)
    p = m.defaults()
    t, road, _ = make_scenario(m, "iso8608", duration=duration, fs=fs, params=p, seed=3)
    if jitter:
        t = t + np.random.default_rng(1).uniform(-2e-4, 2e-4, t.size) * (np.arange(t.size) > 0)
    x0 = 0.3 * m.initial_state() + 0.01 * np.arange(1, m.n_states + 1) / m.n_states
    ref = simulate_ode(m, p, t, road, x0)
    chans = list(m.coords) + [m.coords[0] + "_ddot"] + list(m.ride_heights)
    meas = Measurement(t=t, road=road, measured={c: ref[c] for c in chans}, source="dop853")
    return m, p, meas, x0


def _check(m, p, meas, x0, fast: bool, **kw) -> OutputErrorProblem:
    pr = OutputErrorProblem(m, meas, cost="frobenius", **kw)
    assert pr.fast is fast
    # at the truth: the oracle's record and initial state back
    pred = pr.predict(p)
    scale = max(np.nanmax(np.abs(meas.measured[c])) for c in pr.channels)
    assert np.nanmax(np.abs(pred.residual)) < 1e-7 * scale
    assert pr.normalized_ss(p) < 1e-12
    np.testing.assert_allclose(pred.x0, x0, rtol=0, atol=1e-6 * np.abs(x0).max())
    # elsewhere: the oracle's trajectory from the estimated initial state
    q = {k: (v * 0.7 if m.spec(k).kind == "damping" else v * 1.2 if m.spec(k).kind == "stiffness"
             else v) for k, v in p.items()}
    got = pr.predict(q)
    ref = simulate_ode(m, q, meas.t, meas.road, got.x0)
    for j, c in enumerate(pr.channels):
        s = np.abs(ref[c]).max()
        np.testing.assert_allclose(got.Y[:, j], ref[c], rtol=0, atol=1e-7 * s, err_msg=c)
    ss = float(np.nansum((pr.Ymeas - got.Y) ** 2 * pr.w ** 2))
    assert pr.normalized_ss(q) == pytest.approx(ss / pr.scale, rel=1e-9)
    assert pr.n_fallback == 0
    return pr


@pytest.mark.parametrize("name", ["quarter2", "half4", "full7"])
def test_fast_path_equals_the_oracle(name: str) -> None:
    m, p, meas, x0 = _record(name, 2.0, 200.0)
    pr = _check(m, p, meas, x0, True)
    assert pr.evaluate(p) is not None and set(m.ride_height_channels) & set(pr.channels)
    w = {c: 1.0 + j for j, c in enumerate(pr.channels)}
    _check(m, p, meas, x0, True, weights=w)


@pytest.mark.slow
def test_fast_path_on_a_long_record_scans_the_forced_trajectory() -> None:
    """Beyond ``MAX_DECAY_EXPONENT`` (``E**-N`` would overflow) the forced trajectory is the
    blocked scan's; the cost is still the oracle's."""
    m, p, meas, x0 = _record("quarter2", 28.0, 60.0)
    lam = np.linalg.eigvals(m.state_space(p)[0])
    assert float(-lam.real.min()) * float(meas.t[1] - meas.t[0]) * (meas.t.size - 1) > MAX_DECAY_EXPONENT
    _check(m, p, meas, x0, True)


def test_general_paths_equal_the_oracle() -> None:
    m, p, meas, x0 = _record("half4", 2.0, 200.0)
    gappy = dict(meas.measured)
    gappy[m.coords[0]] = gappy[m.coords[0]].copy()
    gappy[m.coords[0]][50:60] = np.nan
    _check(m, p, Measurement(meas.t, meas.road, gappy, source="gaps"), x0, False)
    m, p, jit, x0 = _record("half4", 2.0, 200.0, jitter=True)
    _check(m, p, jit, x0, False)
