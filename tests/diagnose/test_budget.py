"""`diagnose --maxfev` bounds every fit diagnose makes, the candidate refits included, and
every Levenberg–Marquardt polish counts its finite-difference Jacobians."""
from __future__ import annotations

from typing import Any, Callable

import numpy as np
import pytest

from estimator.diagnose import core, refit
from estimator.diagnose.refit import PhysicalRefit, SensorRefit
from estimator.identify import OutputErrorProblem, Parameters
from estimator.identify.lm import lm_within
from suspid.cli import main
from suspid.models import get_model

from ..conftest import TABLE1
from .conftest import make_measurement


def test_lm_within_counts_the_jacobians() -> None:
    calls = {"n": 0}

    def resid(x: np.ndarray) -> np.ndarray:
        calls["n"] += 1
        return np.array([np.exp(x[0]) - 3.0, x[1] ** 2 - 2.0 + x[2], x[2] * x[0] - 1.0, x[1] - x[2]])

    for budget in (4, 9, 17):
        calls["n"] = 0
        out = lm_within(resid, np.zeros(3), budget, max_nfev=100, diff_step=1e-6)
        # scipy's own max_nfev=budget made up to 4x as many calls (each Jacobian 3 more)
        assert calls["n"] == out.nfev <= budget and out.stopped
        assert out.fun <= float(resid(np.zeros(3)) @ resid(np.zeros(3)))
    calls["n"] = 0
    free = lm_within(resid, np.zeros(3), None, max_nfev=100, diff_step=1e-6)
    assert free.nfev == calls["n"] > 17 and not free.stopped and free.fun < 0.01


def test_maxfev_bounds_every_fit(monkeypatch: pytest.MonkeyPatch) -> None:
    maxfev = 40
    seen: list[tuple[str, int]] = []
    counter = {"n": 0}

    def counting(fn: Callable[..., Any]) -> Callable[..., Any]:
        def wrapped(f: Callable[..., Any], *a: Any, **k: Any) -> Any:
            def g(u: Any) -> Any:
                counter["n"] += 1
                return f(u)
            return fn(g, *a, **k)
        return wrapped

    monkeypatch.setattr(refit, "minimize_log", counting(refit.minimize_log))
    monkeypatch.setattr(refit, "lm_within", counting(refit.lm_within))

    def per_fit(name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        def wrapped(*a: Any, **k: Any) -> Any:
            counter["n"] = 0
            out = fn(*a, **k)
            seen.append((name, counter["n"]))
            return out
        return wrapped

    for cls, meth in ((PhysicalRefit, "fit"), (SensorRefit, "fit"), (SensorRefit, "fit_null")):
        monkeypatch.setattr(cls, meth, per_fit(f"{cls.__name__}.{meth}", getattr(cls, meth)))
    monkeypatch.setattr(core, "reweighted_linear_fit", per_fit("linear refit", core.reweighted_linear_fit))

    # the baseline: every evaluation of the cost or the residual vector during the search
    base_counts: list[int] = []
    inner_fit = core.fit

    def counted_fit(problem: OutputErrorProblem, *a: Any, **k: Any) -> Any:
        n = {"n": 0}
        ss, rv = problem.normalized_ss, problem.residual_vector

        def c_ss(p: Any) -> float:
            n["n"] += 1
            return ss(p)

        def c_rv(p: Any) -> np.ndarray:
            n["n"] += 1
            return rv(p)

        monkeypatch.setattr(problem, "normalized_ss", c_ss)
        monkeypatch.setattr(problem, "residual_vector", c_rv)
        k["with_stderr"] = False
        try:
            return inner_fit(problem, *a, **k)
        finally:
            monkeypatch.setattr(problem, "normalized_ss", ss)
            monkeypatch.setattr(problem, "residual_vector", rv)
            base_counts.append(n["n"])

    monkeypatch.setattr(core, "fit", counted_fit)
    meas = make_measurement(["coulomb_friction:F=120"], noise=0.005)
    m = get_model("quarter2")
    params = Parameters.for_model(m, fix={"m1": TABLE1["m1"], "m2": TABLE1["m2"]},
                                  init={k: 0.7 * TABLE1[k] for k in ("c1", "k1", "c2", "k2")})
    res = core.diagnose(m, meas, params, maxfev=maxfev)
    refits = [n for name, n in seen if name == "PhysicalRefit.fit"]
    assert refits, seen                              # the candidates were refitted
    # without the budget each refit ran ~150 evaluations per parameter and pass
    assert all(n <= maxfev for _, n in seen), seen
    assert base_counts and all(n <= maxfev for n in base_counts), base_counts
    assert all(v.name for v in res.verdicts)
    assert all(f.nfev <= maxfev for f in res.fits.values()), {k: f.nfev for k, f in res.fits.items()}


def test_help_says_what_maxfev_bounds(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["diagnose", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "every fit diagnose makes" in text and "candidate" in text
