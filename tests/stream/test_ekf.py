"""EKF baseline: exact Jacobians (against finite differences), convergence, missing samples."""
from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter

from estimator.ekf.filter import AugmentedEKF, EKFTuning
from estimator.ekf.stream import EKFWindowEstimator
from estimator.stream.drivers import run_arrays
from estimator.stream.wear_streams import damper_wear
from suspid.errors import UsageError
from suspid.models import MODELS, get_model
from suspid.models.quarter1 import Quarter1


@pytest.fixture
def ekf(quarter2):
    return AugmentedEKF(quarter2, quarter2.defaults(), ["c1", "k1", "c2", "k2"],
                        ["x1", "x2_dot", "x1_ddot", "x2_ddot"], dt=0.004,
                        tuning=EKFTuning(substeps=2))


def test_is_a_filterpy_ekf(ekf) -> None:
    assert isinstance(ekf, ExtendedKalmanFilter)
    assert ekf.dim_x == 8 and ekf.dim_z == 4


def test_prediction_uses_the_model_rhs(ekf, quarter2) -> None:
    z = np.array([0.01, -0.004, 0.2, -0.5, 0.8, 1.1, 1.3, 0.9])
    u = np.array([0.003, 0.4])
    p = ekf.param_values(z)
    assert p["c1"] == pytest.approx(0.8 * 1500) and p["k2"] == pytest.approx(0.9 * 2e5)
    assert np.allclose(ekf.f(z, u)[:4], quarter2.rhs(0.0, z[:4], u, p))
    assert np.all(ekf.f(z, u)[4:] == 0)


def _fd(fun, z, eps):
    cols = []
    for i in range(z.size):
        dz = np.zeros_like(z)
        dz[i] = eps[i]
        cols.append((fun(z + dz) - fun(z - dz)) / (2 * eps[i]))
    return np.column_stack(cols)


def test_transition_jacobian_matches_finite_differences(ekf) -> None:
    rng = np.random.default_rng(4)
    for _ in range(5):
        z = np.concatenate([rng.normal(0, 0.02, 2), rng.normal(0, 0.5, 2), rng.uniform(0.5, 1.5, 4)])
        u0, u1 = rng.normal(0, [0.01, 0.3]), rng.normal(0, [0.01, 0.3])
        _, F = ekf.rk4(z, u0, u1, ekf.dt)
        eps = np.concatenate([[1e-6] * 4, [1e-6] * 4])
        Ffd = _fd(lambda zz: ekf.rk4(zz, u0, u1, ekf.dt, with_jacobian=False)[0], z, eps)
        assert np.max(np.abs(F - Ffd)) < 1e-6 * max(1.0, np.max(np.abs(F)))


@pytest.mark.parametrize("substeps", [1, 2, 3])
def test_lean_linear_step_equals_the_rhs_step(quarter2, substeps: int) -> None:
    """The per-step [A | B] path (no effect terms) is the model.rhs RK4 step, to rounding."""
    f = AugmentedEKF(quarter2, quarter2.defaults(), ["c1", "k1", "c2", "k2"], ["x1"],
                     dt=0.004, tuning=EKFTuning(substeps=substeps))
    assert f._linear
    rng = np.random.default_rng(7)
    for _ in range(10):
        z = np.concatenate([rng.normal(0, 0.02, 2), rng.normal(0, 0.5, 2), rng.uniform(0.5, 1.5, 4)])
        u0, u1 = rng.normal(0, [0.01, 0.3]), rng.normal(0, [0.01, 0.3])
        z_lean, F_lean = f.rk4(z, u0, u1, f.dt)
        f._linear = False
        z_rhs, F_rhs = f.rk4(z, u0, u1, f.dt)
        f._linear = True
        np.testing.assert_allclose(z_lean, z_rhs, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(F_lean, F_rhs, rtol=1e-12, atol=1e-13)
        assert np.array_equal(f.rk4(z, u0, u1, f.dt, with_jacobian=False)[0], z_lean)
    # the acceleration channel of the measurement the same way
    g = AugmentedEKF(quarter2, quarter2.defaults(), ["c1", "k1"], ["x1_ddot", "x2_ddot", "x1"],
                     dt=0.004)
    z = np.array([0.01, -0.004, 0.2, -0.5, 0.8, 1.1])
    u = np.array([0.003, 0.4])
    acc = quarter2.rhs(0.0, z[:4], u, g.param_values(z))[2:]
    np.testing.assert_allclose(g.hx(z[:, None], u)[:, 0], [acc[0], acc[1], z[0]], rtol=1e-12)


def test_measurement_jacobian_matches_finite_differences(ekf) -> None:
    rng = np.random.default_rng(5)
    z = np.concatenate([rng.normal(0, 0.02, 2), rng.normal(0, 0.5, 2), rng.uniform(0.5, 1.5, 4)])
    u = np.array([0.002, -0.3])
    H = ekf.HJ(z[:, None], u)
    Hfd = _fd(lambda zz: ekf.hx(zz[:, None], u)[:, 0], z, np.full(z.size, 1e-6))
    assert np.allclose(H, Hfd, rtol=1e-6, atol=1e-6)
    # the acceleration row depends on c1 (c1 (v1 - v2) / m1): nonlinear in the state
    assert H[2, 4] != 0


def test_converges_from_a_wrong_start_and_handles_missing_samples(quarter2) -> None:
    s = damper_wear(quarter2, duration=20.0, wear_start=1e6, wear_end=2e6, seed=2)
    data = dict(s.data)
    data["x1"] = data["x1"].copy()
    data["x1"][3000:3400] = np.nan  # 0.8 s of a missing channel
    start = dict(s.nominal, c1=1000.0, k1=26000.0)
    est = EKFWindowEstimator(quarter2, start, ["c1", "k1"], ["x1", "x2", "x1_ddot"], decimate=2)
    res = []
    run_arrays(s.t, data, 3.0, 1.0, lambda t, d: res.append(est.process(t, d)))
    last = res[-1].event.to_json()
    assert last["params"]["c1"] == pytest.approx(1500.0, rel=0.03)
    assert last["params"]["k1"] == pytest.approx(20000.0, rel=0.03)
    assert last["stderr"]["c1"] < 0.05 * 1500
    assert est.samples == pytest.approx((s.t.size - 1) / 2, abs=2)
    assert all(np.isfinite(r.event.params["c1"]) for r in res)


@pytest.mark.parametrize("name", list(MODELS))
def test_the_filter_runs_on_the_models_affine_pieces(name: str) -> None:
    """The EKF's [A | B] and Jacobian are the model's affine pieces, equal to the model."""
    m = get_model(name)
    p = m.defaults()
    aug = [s.name for s in m.params if s.kind in ("damping", "stiffness")]
    nq, nx, nr = len(m.coords), 2 * len(m.coords), len(m.roads)
    f = AugmentedEKF(m, p, aug, [f"{m.coords[0]}_ddot", m.coords[-1]], dt=0.002,
                     tuning=EKFTuning(substeps=2))
    ref = m.affine(p, aug)
    assert f.pieces.names == tuple(aug) and f.pieces.exact
    np.testing.assert_array_equal(f.pieces.dAB, ref.dAB)
    rng = np.random.default_rng(9)
    for _ in range(3):
        z = np.concatenate([rng.normal(0, 0.02, nq), rng.normal(0, 0.3, nq),
                            rng.uniform(0.6, 1.4, len(aug))])
        u = np.concatenate([rng.normal(0, 0.01, nr), rng.normal(0, 0.3, nr)])
        pv = f.param_values(z)
        J = f.jac(z, u)
        A, _ = m.state_space(pv)
        np.testing.assert_allclose(J[nq:nx, :nx], A[nq:], rtol=0, atol=1e-11 * np.abs(A).max())
        # parameter columns: central differences of the model's own right-hand side in each
        # relative parameter (exact up to rounding: the accelerations are affine in it)
        for j, k in enumerate(aug):
            e = 0.1
            hi = m.rhs(0.0, z[:nx], u, dict(pv, **{k: pv[k] + e * f.nominal[j]}))[nq:]
            lo = m.rhs(0.0, z[:nx], u, dict(pv, **{k: pv[k] - e * f.nominal[j]}))[nq:]
            fd = (hi - lo) / (2 * e)
            np.testing.assert_allclose(J[nq:nx, nx + j], fd, rtol=0,
                                       atol=1e-9 * (np.abs(fd).max() + np.abs(A).max() * 1e-6))
        # the lean step on the pieces is the model.rhs step
        u1 = u + rng.normal(0, 0.01, 2 * nr)
        z_lean, F_lean = f.rk4(z, u, u1, f.dt)
        f._linear = False
        z_rhs, F_rhs = f.rk4(z, u, u1, f.dt)
        f._linear = True
        assert F_lean is not None and F_rhs is not None
        np.testing.assert_allclose(z_lean, z_rhs, rtol=1e-11, atol=1e-14)
        np.testing.assert_allclose(F_lean, F_rhs, rtol=1e-10, atol=1e-12 * np.abs(F_rhs).max())


def test_a_damper_that_enters_non_affinely_is_refused() -> None:
    """The filter's [A | B] is affine in its parameters; a model where it is not is refused."""

    class Squared(Quarter1):
        def matrices(self, p):  # the damping grows as c^2: not affine in c
            M, C, K, Fk, Fc = super().matrices(p)
            return M, C * p["c"] / 1500.0, K, Fk, Fc * p["c"] / 1500.0

    m = Squared()
    assert not m.affine(m.defaults(), ["c"]).exact
    with pytest.raises(UsageError, match="the parameters c do not enter its matrices affinely"):
        AugmentedEKF(m, m.defaults(), ["c"], ["x"], dt=0.002)
    assert AugmentedEKF(m, m.defaults(), ["k"], ["x"], dt=0.002).pieces.exact


def test_input_noise_is_the_steps_sensitivity_to_its_road_samples(quarter2) -> None:
    """Q gains G0 R_u G0^T + G1 R_u G1^T, G0/G1 the RK4 step's sensitivity to its road
    samples; for a short step that is B dt^2/3, B dt/2 (start) and B dt^2/6, B dt/2 (end)
    of the linearly interpolated road's effect on positions and velocities."""
    dt = 1e-4
    f = AugmentedEKF(quarter2, quarter2.defaults(), ["c1", "k1"], ["x1"], dt=dt)
    q0 = f.Q.copy()
    sig = np.array([2e-4, 0.01])
    f.set_input_noise(sig)
    dq = f.Q - q0
    B = f._ab(f.x[4:, 0])[:, 4:] * sig
    expect = np.zeros((6, 6))
    for a in (dt / 3, dt / 6):
        g = np.vstack([B * a * dt, B * dt / 2])
        expect[:4, :4] += g @ g.T
    # (to O(dt A): the wheel mode moves within the step, 0.5 % at dt = 0.1 ms)
    assert np.allclose(dq, expect, rtol=2e-2, atol=1e-3 * np.abs(expect).max())
    assert np.all(dq[4:] == 0) and np.all(dq[:, 4:] == 0)
    assert np.all(np.linalg.eigvalsh(dq) > -1e-12 * np.abs(dq).max())
    f.set_q(dt)  # the random walks are set again, the input noise stays
    assert np.allclose(f.Q, q0 + dq)


@pytest.mark.slow
def test_input_noise_makes_the_stderr_honest_on_a_noisy_road(quarter2) -> None:
    """5 % white noise on the road displacement alone, stiff car, no wear: taking the road
    as exact, the EKF's innovations are 13 times their predicted variance (NIS) and its c1
    error 1.7 times its stderr; with the road's noise as process noise both come to ~1."""
    p = {"m1": 275.0, "c1": 1120.0, "k1": 150000.0, "m2": 27.0, "c2": 3100.0, "k2": 310000.0}
    kw = dict(duration=30.0, fs=500.0, params=p, c_end_fraction=1.0, wear_start=1e6,
              wear_end=2e6, seed=7, quantize=False)
    clean = damper_wear(quarter2, noise={c: 0.0 for c in ("x1", "x2", "x1_ddot", "r", "r_dot")},
                        **kw)
    s = damper_wear(quarter2, noise={c: (0.05 * float(np.std(v)) if c == "r" else 0.0)
                                     for c, v in clean.data.items()}, **kw)
    out = {}
    for inp in (False, True):
        est = EKFWindowEstimator(quarter2, p, ["c1", "k1", "c2", "k2"], ["x1", "x2", "x1_ddot"],
                                 decimate=2, tuning=EKFTuning(input_noise=inp))
        res = []
        run_arrays(s.t, s.data, 4.0, 2.0, lambda t, d: res.append(est.process(t, d)))
        js = [r.event.to_json() for r in res][3:]
        z = np.array([(j["params"]["c1"] - p["c1"]) / j["stderr"]["c1"] for j in js])
        out[inp] = (float(np.sqrt(np.mean(z * z))), float(np.mean([j["nis"] for j in js])))
    assert out[False][0] > 1.4 and out[False][1] > 5.0        # 1.67, 12.8 measured
    assert 0.7 < out[True][0] < 1.3 and out[True][1] < 1.5     # 1.02, 0.56
