"""``estimator.identify.simplex.nelder_mead`` is bit-identical to scipy's Nelder–Mead."""
from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize

from estimator.identify.simplex import SimplexWarning, nelder_mead

ROOT = Path(__file__).resolve().parents[2]


def rosen(x: np.ndarray) -> float:
    return float(np.sum(100.0 * (x[1:] - x[:-1] ** 2) ** 2 + (1 - x[:-1]) ** 2))


def quad(x: np.ndarray) -> float:
    d = x - np.arange(1, x.size + 1)
    return float(d @ d + 0.3 * d[0] * d[-1])


def inf_region(x: np.ndarray) -> float:
    """Rosenbrock with an infeasible (inf) half-plane."""
    if x[0] > 0.8:
        return np.inf
    return rosen(x)


def inf_far(x: np.ndarray) -> float:
    if not np.all(np.abs(x) < 2.0):
        return np.inf
    return quad(x)


def returns_array(x: np.ndarray) -> np.ndarray:
    return np.array([quad(x)])


def flat(x: np.ndarray) -> float:
    """Piecewise constant: many ties, exercises the sort and shrinks."""
    return float(np.floor(4 * np.sum(np.abs(x))))


def compare(fun: Callable[[np.ndarray], Any], x0: Any, **kw: Any) -> None:
    """Run both and require bit-identical results and identical call sequences."""
    calls_s: list[np.ndarray] = []
    calls_o: list[np.ndarray] = []

    def fs(x: np.ndarray) -> Any:
        calls_s.append(x.copy())
        return fun(x)

    def fo(x: np.ndarray) -> Any:
        calls_o.append(x.copy())
        return fun(x)

    bounds = kw.pop("bounds", None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = minimize(fs, x0, method="Nelder-Mead", bounds=bounds, options=kw)
        got = nelder_mead(fo, x0, bounds=bounds, **kw)
    assert got.nfev == ref.nfev
    assert got.nit == ref.nit
    assert got.status == ref.status
    assert got.success == ref.success
    assert got.message == ref.message
    assert np.array_equal(got.x, ref.x, equal_nan=True)
    assert got.x.dtype == ref.x.dtype
    assert np.array_equal(got.fun, ref.fun, equal_nan=True)
    assert np.array_equal(got.final_simplex[0], ref.final_simplex[0], equal_nan=True)
    assert np.array_equal(got.final_simplex[1], ref.final_simplex[1], equal_nan=True)
    assert len(calls_s) == len(calls_o)
    for a, b in zip(calls_s, calls_o):
        assert np.array_equal(a, b, equal_nan=True)


X4 = np.array([-1.2, 1.0, 0.5, 0.0])


@pytest.mark.parametrize("fun,x0", [
    (rosen, [-1.2, 1.0]),
    (rosen, X4),
    (quad, [0.0, 0.0, 0.0]),
    (quad, [0, 3]),                      # integer start
    (inf_region, [-1.2, 1.0]),
    (inf_far, [1.9, -1.9, 0.0]),
    (returns_array, [0.5, 0.5]),
    (flat, [1.0, -2.0, 0.5]),
    (quad, [7.0]),
])
@pytest.mark.parametrize("opts", [
    {},
    {"xatol": 1e-8, "fatol": 1e-12},
    {"maxfev": 37},
    {"maxiter": 15},
    {"maxiter": 30, "maxfev": 45},
    {"maxfev": np.inf},
    {"maxiter": np.inf, "xatol": 1e-3},
])
def test_matches_scipy_default_simplex(fun: Callable, x0: Any, opts: dict) -> None:
    compare(fun, x0, **opts)


@pytest.mark.parametrize("fun", [rosen, quad, inf_far, flat])
@pytest.mark.parametrize("n", [2, 3, 4])
def test_matches_scipy_initial_simplex(fun: Callable, n: int) -> None:
    u0 = np.full(n, 0.3)
    sim = np.vstack([u0] + [u0 + 0.3 * e for e in np.eye(n)])
    compare(fun, sim[0], initial_simplex=sim, xatol=1e-7, fatol=1e-14, maxfev=400)


@pytest.mark.parametrize("n", [5, 6])
@pytest.mark.parametrize("adaptive", [False, True])
@pytest.mark.parametrize("fun", [rosen, quad])
def test_matches_scipy_adaptive(n: int, adaptive: bool, fun: Callable) -> None:
    compare(fun, np.linspace(-1.0, 1.0, n), adaptive=adaptive, maxfev=900)
    u0 = np.zeros(n)
    sim = np.vstack([u0] + [u0 + 0.2 * e for e in np.eye(n)])
    compare(fun, u0, initial_simplex=sim, adaptive=adaptive, maxfev=500, xatol=1e-7,
            fatol=1e-14)


BOUNDS = [
    [(-2.0, 0.5), (0.0, 2.0)],
    [(None, 0.5), (-np.inf, np.inf)],
    [(-np.inf, 0.9), (0.2, None)],
    [(0.0, 0.0), (-1.0, 1.0)],           # a fixed coordinate
    [(np.array(-1.0), 1.05), (0.9, 1.0)],  # start at the upper bound (reflection)
]


@pytest.mark.parametrize("bounds", BOUNDS)
@pytest.mark.parametrize("fun", [rosen, inf_region, quad])
@pytest.mark.parametrize("x0", [[-1.2, 1.0], [1.0, 1.0], [3.0, -3.0]])
def test_matches_scipy_bounds(bounds: list, fun: Callable, x0: list) -> None:
    compare(fun, x0, bounds=bounds)
    sim = np.array([[0.0, 0.5], [0.7, 0.5], [0.0, 1.4]])
    compare(fun, x0, bounds=bounds, initial_simplex=sim, maxfev=150)


def test_bounds_warning_and_errors() -> None:
    with pytest.warns(SimplexWarning):
        nelder_mead(quad, [3.0, 0.0], bounds=[(-1, 1), (-1, 1)])
    with pytest.raises(ValueError):
        nelder_mead(quad, [0.0, 0.0], bounds=[(1, -1), (-1, 1)])
    with pytest.raises(ValueError):
        nelder_mead(quad, [0.0, 0.0], bounds=[(-1, 1)] * 3)
    with pytest.raises(ValueError):
        nelder_mead(quad, [0.0, 0.0], initial_simplex=np.zeros((2, 2)))
    with pytest.raises(ValueError):
        nelder_mead(lambda x: np.zeros(2), [0.0, 0.0])


def test_budget_runs_out_inside_shrink() -> None:
    """Every maxfev cut of a run with shrinks, so some land inside a shrink step."""
    def f(x: np.ndarray) -> float:
        return flat(x) + 1e-3 * float(x @ x)

    x0 = [1.0, -2.0, 0.5]
    full = nelder_mead(f, x0, maxfev=120)
    for m in range(0, full.nfev + 2):
        compare(f, x0, maxfev=m)
    sim = np.array([[1.0, 1.0], [1.3, 1.0], [1.0, 1.3]])
    for m in range(0, 40):
        compare(flat, sim[0], initial_simplex=sim, maxfev=m, adaptive=True)


def test_shrink_cut_happens() -> None:
    """The cut-in-shrink case is really exercised: a vertex moved but not re-evaluated."""
    hits = 0
    for m in range(4, 60):
        seen: list[bytes] = []

        def f(x: np.ndarray) -> float:
            seen.append(x.tobytes())
            return flat(x)

        r = nelder_mead(f, [1.0, -2.0, 0.5], maxfev=m)
        hits += any(v.tobytes() not in seen for v in r.final_simplex[0])
    assert hits > 0


finite = st.floats(-3.0, 3.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(1, 4), data=st.data(), adaptive=st.booleans(),
       use_sim=st.booleans(), use_bounds=st.booleans(),
       maxfev=st.one_of(st.none(), st.integers(0, 300)))
def test_random_quadratics(n: int, data: st.DataObject, adaptive: bool, use_sim: bool,
                           use_bounds: bool, maxfev: int | None) -> None:
    a = np.array(data.draw(st.lists(finite, min_size=n * n, max_size=n * n))).reshape(n, n)
    h = a @ a.T + 0.1 * np.eye(n)
    c = np.array(data.draw(st.lists(finite, min_size=n, max_size=n)))
    x0 = np.array(data.draw(st.lists(finite, min_size=n, max_size=n)))

    def f(x: np.ndarray) -> float:
        d = x - c
        return float(d @ h @ d)

    kw: dict[str, Any] = {"adaptive": adaptive, "maxfev": maxfev}
    if use_sim:
        kw["initial_simplex"] = np.vstack([x0] + [x0 + 0.3 * e for e in np.eye(n)])
        kw["xatol"], kw["fatol"] = 1e-7, 1e-14
    if use_bounds:
        lo = data.draw(st.lists(st.one_of(st.none(), st.floats(-3.0, 0.0)), min_size=n,
                                max_size=n))
        hi = data.draw(st.lists(st.one_of(st.just(np.inf), st.floats(0.0, 3.0)),
                                min_size=n, max_size=n))
        kw["bounds"] = list(zip(lo, hi))
    compare(f, x0, **kw)


def test_minimize_log_unchanged() -> None:
    """``minimize_log`` with the replica equals the scipy-driven original, restarts included."""
    from estimator.identify import solver as nm_mod

    def cost(u: np.ndarray) -> float:
        if not np.all(np.abs(u) < 30):
            return np.inf
        return rosen(u + 1.0) + 1e-3

    def scipy_nm(fun: Callable, x0: Any, **kw: Any) -> Any:
        bounds = kw.pop("bounds")
        return minimize(fun, x0, method="Nelder-Mead", bounds=bounds, options=kw)

    for bounds in (None, [(-0.5, 0.5), (-np.inf, 2.0), (None, None)]):
        for n in (2, 3, 5):
            b = None if bounds is None else bounds[:n] + [(None, None)] * (n - len(bounds))
            got = nm_mod.minimize_log(cost, np.zeros(n), maxfev=800, bounds=b)
            orig = nm_mod.nelder_mead
            nm_mod.nelder_mead = scipy_nm  # type: ignore[assignment]
            try:
                ref = nm_mod.minimize_log(cost, np.zeros(n), maxfev=800, bounds=b)
            finally:
                nm_mod.nelder_mead = orig  # type: ignore[assignment]
            assert np.array_equal(got.u, ref.u) and got.fun == ref.fun
            assert (got.nfev, got.restarts, got.converged) == (ref.nfev, ref.restarts,
                                                              ref.converged)
            assert np.array_equal(got.final_simplex, ref.final_simplex)


def test_minimize_log_adaptive_choice() -> None:
    """``adaptive`` picks the coefficients (default: adapted above four parameters): the
    same run as scipy's with that option, and the two choices differ in six dimensions."""
    from estimator.identify import solver as nm_mod

    def cost(u: np.ndarray) -> float:
        return rosen(u + 1.0) + 1e-3

    n = 6
    sim = np.vstack([np.zeros(n)] + [0.05 * e for e in np.eye(n)])
    runs = {}
    for adaptive in (None, True, False):
        got = nm_mod.minimize_log(cost, np.zeros(n), maxfev=600, restarts=0, xatol=1e-4,
                                  fatol=np.inf, initial_simplex=sim, adaptive=adaptive)
        ref = minimize(cost, sim[0], method="Nelder-Mead",
                       options={"initial_simplex": sim, "xatol": 1e-4, "fatol": np.inf,
                                "maxfev": 600, "adaptive": adaptive is not False})
        assert np.array_equal(got.u, ref.x) and got.nfev == ref.nfev
        runs[adaptive] = got
    assert np.array_equal(runs[None].u, runs[True].u)
    assert runs[False].nfev != runs[True].nfev


def test_monitor_imports_no_scipy_optimize() -> None:
    code = ("import sys, estimator.identify, estimator.stream.window; "
            "print('scipy.optimize' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, check=True)
    assert out.stdout.strip() == "False"
