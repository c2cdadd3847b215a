"""A monitor window's fit on the one output-error problem: the stderr from the final
simplex's secant, Gauss-Newton steps, the drifting window, the fast cost's guard."""
from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.identify import OutputErrorProblem, Parameters, finish
from estimator.identify.solver import minimize_log
from estimator.stream.wear_streams import damper_wear
import estimator.identify.problem as pm
import estimator.stream.windowfit as wf
from estimator.stream.windowfit import WindowFit, small_inverse
from suspid.io.csvio import Measurement
from suspid.simulate import outputs, simulate_states

FIX = ("m1", "m2", "c2", "k2")


@pytest.fixture(scope="module")
def window(quarter2):
    """One 3 s window of the damper-wear stream at 250 Hz, as the monitor fits it."""
    s = damper_wear(quarter2, duration=12.0, fs=500.0, seed=2)
    sl = slice(1000, 2501, 2)
    road = {k: s.data[k][sl] for k in ("r", "r_dot")}
    meas = Measurement(s.t[sl].copy(), road, {c: s.data[c][sl] for c in ("x1", "x2", "x1_ddot")},
                       source="window")
    params = Parameters.for_model(quarter2, fix={k: s.nominal[k] for k in FIX})
    return s, meas, params


def _window(model, meas, params):
    """The window's problem as the monitor builds it."""
    return OutputErrorProblem(model, meas, affine=model.affine(params.valuesdict(), params.free),
                              ride_heights=False)


def _points(p0, n=12, spread=0.3, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        q = dict(p0)
        for k in ("c1", "k1"):
            q[k] = p0[k] * math.exp(rng.normal(0.0, spread))
        out.append(q)
    return out


def test_window_finish_equals_the_core_finish(quarter2, window) -> None:
    s, meas, params = window
    ref = OutputErrorProblem(quarter2, meas)
    prob = _window(quarter2, meas, params)
    lean = WindowFit(prob)
    p = dict(s.nominal)
    p["c1"] *= 1.004  # near, not at, the optimum
    a = finish(ref, params, p, 12, True)
    # forward differences (no simplex given)
    b = lean.finish(params, p, 12, True)
    # secant through a small simplex around p (as Nelder-Mead's final simplex)
    simplex = [p, dict(p, c1=p["c1"] * math.exp(2e-3)),
               dict(p, k1=p["k1"] * math.exp(1.5e-3), c1=p["c1"] * math.exp(-1e-3))]
    for q in simplex:
        prob.normalized_ss(q)
    c = lean.finish(params, p, 12, True, simplex=simplex)
    for res, tol in ((b, 1e-4), (c, 2e-2)):
        assert res.identifiable == a.identifiable
        assert res.cost == pytest.approx(a.cost, rel=1e-10)
        assert res.warnings == a.warnings
        for k in ("c1", "k1"):
            assert res.stderr[k] == pytest.approx(a.stderr[k], rel=tol)
        for ch in ("x1", "x2", "x1_ddot"):
            assert res.rms_residual[ch] == pytest.approx(a.rms_residual[ch], rel=1e-9)
        assert np.allclose(res.x0, a.x0, rtol=1e-7, atol=1e-12)
        assert np.allclose(res.singular_values, a.singular_values, rtol=tol)


def test_missing_samples_and_irregular_grids_take_the_general_path(quarter2, window) -> None:
    """A gap or a jittered grid: no fast path (the window's finish is the core's)."""
    s, meas, params = window
    x1 = meas.measured["x1"].copy()
    x1[100:110] = np.nan
    gappy = Measurement(meas.t, meas.road, dict(meas.measured, x1=x1), source="window")
    t2 = meas.t.copy()
    t2[5:] += 1e-3
    irregular = Measurement(t2, meas.road, meas.measured, source="window")
    q = dict(s.nominal)
    for m in (gappy, irregular):
        prob = _window(quarter2, m, params)
        assert not prob.fast and prob.evaluate(q) is None and not WindowFit(prob).drift_ok
        a = WindowFit(prob).finish(params, q, 3, True)
        b = finish(OutputErrorProblem(quarter2, m), params, q, 3, True, with_stderr=True)
        assert a.cost == b.cost and a.stderr == b.stderr


def test_small_inverse() -> None:
    rng = np.random.default_rng(4)
    for n in (1, 2, 3):
        M = rng.normal(size=(n, n)) + 3 * np.eye(n)
        inv, cond = small_inverse(M)
        assert np.allclose(inv, np.linalg.inv(M))
        assert cond == pytest.approx(np.linalg.cond(M, 1))
    assert small_inverse(np.array([[1.0, 2.0], [2.0, 4.0]])) == (None, math.inf)


def test_drift_residual_equals_the_lean_path_without_drift_and_fits_a_ramp(quarter2, window) -> None:
    """With zero rates the drifting window is the constant one (any chunk length); on a
    window whose c1 ramps, the true end value with the true rate fits far better than any
    constant c1 of a scan."""
    s, meas, params = window
    prob = _window(quarter2, meas, params)
    lean = WindowFit(prob)
    assert lean.drift_ok
    t_end = float(meas.t[-1])
    for q in _points(s.nominal, n=4):
        a = prob.normalized_ss(q)
        for chunk in (0.02, 0.1, 0.35):
            assert lean.drift_ss(q, {"c1": 0.0}, t_end, chunk) == pytest.approx(a, rel=1e-8)
    # a ramp: c1 falls 6.25 %/s over the whole stream
    w = damper_wear(quarter2, duration=8.0, fs=500.0, wear_start=0.0, wear_end=8.0, seed=4,
                    quantize=False, noise={c: 0.0 for c in ("x1", "x2", "x1_ddot")})
    sl = slice(2000, 3501, 2)
    m2 = Measurement(w.t[sl].copy(), {k: w.data[k][sl] for k in ("r", "r_dot")},
                     {c: w.data[c][sl] for c in ("x1", "x2")}, source="window")
    prob = _window(quarter2, m2, params)
    te = float(m2.t[-1])
    c_end = float(np.interp(te, w.t, w.truth["c1"]))
    p = dict(w.nominal, c1=c_end)
    g = -0.0625 * w.nominal["c1"] / c_end  # relative to the end value, 1/s
    ramp = WindowFit(prob).drift_ss(p, {"c1": g}, te, 0.05)
    best_const = min(prob.normalized_ss(dict(w.nominal, c1=c_end * f))
                     for f in np.linspace(1.0, 1.25, 26))
    assert ramp < 0.05 * best_const


def test_drift_sensitivity_equals_finite_differences_of_the_drifting_window(quarter2, window) -> None:
    """The sensitivity columns (one linear simulation each) are the derivatives of the
    drifting window's prediction: with respect to the log of a parameter, the lean
    path's own (constant window), and with respect to the rate, that of
    :meth:`drift_residual` with short chunks; both at zero rate, at parameters that fit."""
    s, meas, params = window
    m = Measurement(meas.t, meas.road, {c: meas.measured[c] for c in ("x1", "x2")},
                    source="window")
    prob = WindowFit(_window(quarter2, m, params))
    te = float(m.t[-1])
    # at the window's true parameters: the residual is noise (the Gauss-Newton, Kaufman
    # form of the variable projection drops a term proportional to it)
    p = dict(s.nominal, c1=float(np.interp(0.5 * (m.t[0] + te), s.t, s.truth["c1"])))
    got = prob.drift_sensitivity(p, ["c1", "k1"], te)
    assert got is not None
    Ja, Jg = got
    R0 = prob.residual(p)
    Rd = prob.drift_residual(p, {}, te, 0.01)
    assert R0 is not None and Rd is not None
    e = 1e-6
    for j, k in enumerate(["c1", "k1"]):
        Ra = prob.residual(dict(p, **{k: p[k] * math.exp(e)}))
        assert Ra is not None
        fa = -(Ra - R0).ravel() / e
        Rg = prob.drift_residual(p, {k: e}, te, 0.01)
        assert Rg is not None
        fg = -(Rg - Rd).ravel() / e
        # FOH of the sensitivity forcing at 250 Hz: ~0.1-0.5 % of the column
        assert np.linalg.norm(fa - Ja[:, j]) < 0.01 * np.linalg.norm(fa)
        assert np.linalg.norm(fg - Jg[:, j]) < 0.01 * np.linalg.norm(fg)
    # a parameter in the road-rate input (tyre damping c2 with B_v = c2 / m2): not available
    assert prob.drift_sensitivity(p, ["c2"], te) is None


def test_cost_skips_the_residual_pass_unless_the_terms_cancel(quarter2, window) -> None:
    """The fast cost is ``||R0||^2 - rhs . sol`` without forming the residual; on a noise-free
    window at its true parameters that difference cancels to rounding, so the residual is
    formed and summed instead (the cost then is at rounding level, not ``~1e-16 ||R0||^2``
    of cancellation). Either way the residual is the general path's."""
    s, meas, params = window
    # noisy window, away from its optimum: no residual pass for the cost
    lean = _window(quarter2, meas, params)
    ref = OutputErrorProblem(quarter2, meas)
    ref.fast = False
    q = _points(s.nominal, n=1)[0]
    assert lean.normalized_ss(q) == pytest.approx(ref.normalized_ss(q), rel=1e-10)
    ev = lean.evaluate(q)
    assert ev is not None and ev._R is None
    rv = lean.residual_vector(q)  # formed on first use
    assert np.max(np.abs(rv - ref.residual_vector(q))) <= 1e-9 * np.max(np.abs(rv))
    assert float(rv @ rv) == pytest.approx(ev.ss, rel=1e-10)
    # noise-free window simulated by the model from a non-zero initial state
    p = dict(s.nominal)
    x0 = np.array([0.01, -0.004, 0.05, 0.2])
    X = simulate_states(quarter2, p, meas.t, ref.U, x0)
    out = outputs(quarter2, p, X, ref.U)
    clean = Measurement(meas.t, meas.road, {c: out[c] for c in ("x1", "x2")}, source="window")
    lean0 = _window(quarter2, clean, params)
    v = lean0.normalized_ss(p)
    ev0 = lean0.evaluate(p)
    assert ev0 is not None and ev0._R is not None  # the guard formed the residual
    r0 = ev0.R0.ravel()
    assert ev0.ss < pm.SS_GUARD * float(r0 @ r0)
    r = ev0.R.ravel()
    assert v == float(r @ r) / lean0.scale
    assert 0.0 <= v < 1e-20
    general = OutputErrorProblem(quarter2, clean)
    general.fast = False
    assert general.normalized_ss(p) < 1e-20


@pytest.fixture(scope="module")
def window_optimum(quarter2, window):
    """The window's fit and its optimum (Nelder-Mead to 1e-9, every parameter)."""
    s, meas, params = window
    free = params.free
    prob = _window(quarter2, meas, params)
    lean = WindowFit(prob)
    base = dict(s.nominal)

    def cost(u: np.ndarray) -> float:
        return prob.normalized_ss({**base, **{k: base[k] * math.exp(x) for k, x in zip(free, u)}})

    best = minimize_log(cost, np.zeros(len(free)), step=0.05, restarts=3, xatol=1e-9,
                        fatol=math.inf, maxfev=4000)
    return lean, {**base, **{k: base[k] * math.exp(x) for k, x in zip(free, best.u)}}


def test_gauss_newton_step_lands_near_the_window_optimum(window, window_optimum) -> None:
    """One Gauss-Newton step from 0.3-0.4 % off the window's optimum (where a loose
    Nelder-Mead stops) lands within a tenth of that distance and lowers the cost; from
    30 % off it goes no farther than the trust region (and still lowers the cost)."""
    params = window[2]
    free = params.free
    lean, opt = window_optimum
    off = dict(opt, c1=opt["c1"] * math.exp(0.004), k1=opt["k1"] * math.exp(-0.003))
    q = lean.gauss_newton(free, off, 1).params
    assert q is not None
    d0 = max(abs(math.log(off[k] / opt[k])) for k in free)
    d1 = max(abs(math.log(q[k] / opt[k])) for k in free)
    assert d1 < 0.1 * d0
    assert lean.problem.normalized_ss(q) < lean.problem.normalized_ss(off)
    far = dict(opt, c1=opt["c1"] * 1.3)
    q = lean.gauss_newton(free, far, 1).params
    assert q is not None and lean.problem.normalized_ss(q) < lean.problem.normalized_ss(far)
    assert max(abs(math.log(q[k] / far[k])) for k in free) <= wf.GAUSS_NEWTON_MAX_STEP + 1e-12


def test_gauss_newton_steps_on_one_jacobian_and_its_reuse_for_the_stderr(window, window_optimum,
                                                                         monkeypatch) -> None:
    """Further steps on the first Jacobian land nearer the optimum than one step and cost
    one evaluation each; ``finish`` takes that Jacobian for the stderr instead of a second
    forward difference (its stderr within 5 % from 1.2 % off, no evaluation)."""
    params = window[2]
    free = params.free
    lean, opt = window_optimum
    off = dict(opt, c1=opt["c1"] * math.exp(0.012), k1=opt["k1"] * math.exp(-0.009))
    one = lean.gauss_newton(free, off, 1)
    three = lean.gauss_newton(free, off, 3)
    assert one.params is not None and three.params is not None
    assert one.nfev == len(free) + 1 and len(free) + 1 < three.nfev <= len(free) + 3
    d1 = max(abs(math.log(one.params[k] / opt[k])) for k in free)
    d3 = max(abs(math.log(three.params[k] / opt[k])) for k in free)
    assert d3 < d1
    assert lean.problem.normalized_ss(three.params) <= lean.problem.normalized_ss(one.params)
    ref = lean.finish(params, three.params, 0, True)
    monkeypatch.setattr(lean, "_forward_jacobian", lambda *a, **k: pytest.fail("evaluated"))
    got = lean.finish(params, three.params, 0, True, jacobian=three.jacobian)
    for k in free:
        assert got.stderr[k] == pytest.approx(ref.stderr[k], rel=0.05)
