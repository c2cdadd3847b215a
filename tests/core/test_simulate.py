"""The fast modal simulator agrees with a high-accuracy ODE solution of model.rhs."""
from __future__ import annotations

import numpy as np
import pytest

import suspid.simulate as sim
from suspid.excitation import bump_profile, make_scenario
from suspid.models import MODELS as REGISTRY
from suspid.models import get_model
from suspid.simulate import simulate, simulate_ode

MODELS = list(REGISTRY)  # every registered model gets the same tests


def _rel_err(a: dict, b: dict, chans) -> float:
    return max(float(np.max(np.abs(a[c] - b[c])) / np.max(np.abs(b[c]))) for c in chans)


@pytest.mark.parametrize("name", MODELS)
@pytest.mark.parametrize("scenario", ["initial", "curb", "bump", "iso8608"])
def test_modal_matches_dop853(name: str, scenario: str) -> None:
    m = get_model(name)
    p = m.defaults()
    t, road, x0 = make_scenario(m, scenario, duration=1.5, fs=500, params=p, v_kmh=30)
    if scenario != "initial":
        x0 = np.linspace(0.01, 0.04, m.n_states)  # road and initial state together
    fast = simulate(m, p, t, road, x0)
    # the reference sees the same piecewise-linear road (FOH), integrated per sample
    ref = simulate_ode(m, p, t, {k: v for k, v in road.items() if not k.endswith("_dot")}, x0,
                       method="DOP853", rtol=1e-10, atol=1e-13)
    chans = [c for c in m.channels if not c.endswith("_ddot")]
    assert _rel_err(fast, ref, chans) < 1e-6


def test_smooth_bump_converges_to_continuous_solution() -> None:
    """With the analytic bump as input, the FOH error shrinks as O(h^2) toward the ODE."""
    m = get_model("quarter2")
    p = m.defaults()

    def road_fn(tt: float) -> np.ndarray:
        r, rd = bump_profile(np.array([tt]), 0.1, 3.0, 20.0, 0.1)
        return np.array([r[0], rd[0]])

    errs = []
    for fs in (500, 2000):
        t = np.arange(0, 1.5, 1 / fs)
        r, rd = bump_profile(t, 0.1, 3.0, 20.0, 0.1)
        fast = simulate(m, p, t, {"r": r, "r_dot": rd})
        ref = simulate_ode(m, p, t, road_fn=road_fn, rtol=1e-10, atol=1e-13)
        errs.append(_rel_err(fast, ref, ["x1", "x2", "x1_dot", "x2_dot"]))
    assert errs[1] < 1e-4
    assert errs[0] / errs[1] > 10  # second order: 4x the rate -> ~16x smaller


def test_nonuniform_grid_path_is_exact() -> None:
    m = get_model("quarter2")
    p = m.defaults()
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.0008, 0.0012, 800))
    r = 0.05 * np.sin(2 * np.pi * 2 * t)
    fast = simulate(m, p, t, {"r": r}, np.array([0.02, 0.0, 0.1, 0.0]))
    ref = simulate_ode(m, p, t, {"r": r}, np.array([0.02, 0.0, 0.1, 0.0]))
    assert _rel_err(fast, ref, ["x1", "x2", "x1_dot", "x2_dot"]) < 1e-6


def test_accelerations_match_rhs() -> None:
    m = get_model("half4")
    p = m.defaults()
    t, road, x0 = make_scenario(m, "bump", duration=1.0, fs=400, params=p)
    out = simulate(m, p, t, road, x0)
    k = 150
    x = np.array([out[c][k] for c in m.state_names])
    u = np.array([out[c][k] for c in m.input_names])
    acc = m.rhs(t[k], x, u, p)[4:]
    assert np.allclose(acc, [out[f"{c}_ddot"][k] for c in m.coords], rtol=1e-9, atol=1e-12)


def test_half4_rear_road_is_delayed_front_road() -> None:
    m = get_model("half4")
    p = m.defaults()
    t, road, _ = make_scenario(m, "bump", duration=2.0, fs=1000, params=p, v_kmh=36)
    lag = int(round((p["a1"] + p["a2"]) / 10.0 * 1000))
    assert np.allclose(road["r2"][lag:], road["r1"][:-lag], atol=1e-9)
    assert road["r1"].max() == pytest.approx(0.1, rel=1e-3)


def test_epoch_stamped_grid_is_uniform_and_takes_the_fast_path() -> None:
    """Real loggers stamp epoch seconds (~1.6e9 s, float spacing 2.4e-7 s): such a grid is
    uniform, and simulating on it equals simulating on the same grid from zero (it once fell
    to the per-sample matrix-exponential loop: minutes per fit on a 10-minute log)."""
    from suspid.simulate import uniform_step

    t0 = np.arange(60_000) * 0.01
    te = 1_627_280_000.0 + t0
    assert np.ptp(np.diff(te)) > 1e-8                     # rounding scatter of the stamps
    assert uniform_step(te) == pytest.approx(0.01, rel=1e-9)
    assert uniform_step(np.r_[te[:100], te[100:] + 0.003]) is None   # a real jump is not uniform
    m = get_model("quarter2")
    _, road, _ = make_scenario(m, "iso8608", duration=599.99, fs=100.0)
    a = simulate(m, m.defaults(), t0, road)
    b = simulate(m, m.defaults(), te, road)
    np.testing.assert_allclose(b["x1"], a["x1"], rtol=0, atol=1e-9 * np.abs(a["x1"]).max())


@pytest.mark.parametrize("name", MODELS)
def test_jittered_grid_steps_the_modes_exactly(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A logger's jittered time base (every interval different) steps the modes interval by
    interval: the same states as the per-interval matrix exponentials, without them (that
    path once cost a matrix exponential per sample: 80 s for a 200-row quarter1 CSV)."""
    m = get_model(name)
    p = m.defaults()
    t, road, _ = make_scenario(m, "bump", duration=0.4, fs=500.0, params=p, t0=0.05)
    t = t + np.random.default_rng(4).uniform(-2e-4, 2e-4, t.size) * (np.arange(t.size) > 0)
    assert sim.uniform_step(t) is None
    x0 = np.linspace(0.01, 0.03, m.n_states)
    U = sim.road_matrix(m, t, road)
    ref = sim._simulate_states_loop(m, p, t, U, x0)

    def no_expm(*args: object, **kwargs: object) -> None:
        raise AssertionError("per-interval matrix exponentials on a diagonalisable model")

    monkeypatch.setattr(sim, "_simulate_states_loop", no_expm)
    X = sim.simulate_states(m, p, t, U, x0)
    np.testing.assert_allclose(X, ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    free = sim.simulate_states(m, p, t, np.zeros_like(U), x0)
    monkeypatch.undo()
    np.testing.assert_allclose(free, sim._simulate_states_loop(m, p, t, np.zeros_like(U), x0),
                               rtol=0, atol=1e-10 * np.abs(x0).max())
