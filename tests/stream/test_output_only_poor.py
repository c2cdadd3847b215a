"""Output-only mode on poor data: fits stuck at a bound, low sample rates, gravity left in
the channel, an invalid-marker step, and missing samples counted once."""
from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.output_only import OutputOnlyEstimator, fit_carma
from estimator.stream.drivers import run_arrays
from estimator.stream.events import Estimate, Skip
from estimator.stream.wear_streams import damper_wear


@pytest.fixture(scope="module")
def healthy(quarter2):  # type: ignore[no-untyped-def]
    """60 s of body acceleration at 100 Hz, no wear (body mode 1.26 Hz, zeta 0.27)."""
    s = damper_wear(quarter2, duration=60.0, fs=100.0, wear_start=59.0, c_end_fraction=1.0,
                    channels=("x1_ddot",), seed=3, chunk_s=0.5)
    return s.t, np.asarray(s.data["x1_ddot"], dtype=float)


def _one(t: np.ndarray, y: np.ndarray, **kw: float) -> tuple[OutputOnlyEstimator, dict]:
    est = OutputOnlyEstimator("x1_ddot", **kw)
    return est, est.process(t, {"x1_ddot": y}).event.to_json()


def test_a_fit_at_the_damping_bound_has_no_stderr_and_is_not_tracked() -> None:
    """A pure 1.5 Hz tone (no damped mode): the fit parks at zeta 0.02 (was: a standard
    error of 1e-4 and no warning)."""
    t = np.arange(0, 60, 0.01)
    y = np.sin(2 * np.pi * 1.5 * t) + np.random.default_rng(1).normal(0, 1e-3, t.size)
    mode = fit_carma(y, 100.0)
    assert mode.zeta == pytest.approx(0.02, rel=1e-3) and "zeta 0.02" in mode.at_bound
    assert math.isnan(mode.zeta_se) and math.isnan(mode.f_se)
    est = OutputOnlyEstimator("x1_ddot")
    res = est.process(t, {"x1_ddot": y})
    line = res.event.to_json()
    assert isinstance(res.event, Estimate) and res.values is None
    assert all(math.isnan(v) for v in line["stderr"].values())
    assert any("stopped at zeta 0.02 (the lower bound)" in w for w in line["warnings"])


def test_a_fit_at_the_frequency_bound_is_flagged() -> None:
    """The strongest content above the band: the frequency parks at the band's top."""
    t = np.arange(0, 60, 0.01)
    rng = np.random.default_rng(2)
    y = np.sin(2 * np.pi * 8.0 * t) * 5 + np.diff(np.concatenate(([0], rng.normal(0, 1, t.size))))
    mode = fit_carma(y, 100.0)
    if mode.at_bound:
        assert "Hz (the" in mode.at_bound and math.isnan(mode.f_se)
    # whichever bound it reached, a value at 5 Hz is never given a standard error
    assert not (abs(mode.f_hz - 5.0) < 5e-3 and math.isfinite(mode.f_se))


def test_healthy_window_keeps_its_stderr(healthy) -> None:  # type: ignore[no-untyped-def]
    t, y = healthy
    _, line = _one(t, y)
    assert line["type"] == "estimate" and line["stderr"]["f_body"] > 0
    assert line["warnings"] == []


def test_a_slow_stream_is_fitted_below_its_nyquist(healthy) -> None:  # type: ignore[no-untyped-def]
    """9.8 Hz stream: Nyquist 4.9 Hz, fitted to 3.92 Hz (was: fitted to 5 Hz, past it)."""
    t, y = healthy
    t2 = np.arange(0, 60, 1 / 9.8)
    y2 = np.interp(t2, t, y)
    _, line = _one(t2, y2)
    assert any(w.startswith("fitted up to 3.92 Hz, not 5 Hz: the stream's 9.8 Hz sample rate")
               for w in line["warnings"]), line
    t3 = np.arange(0, 60, 1 / 5.0)
    _, skip = _one(t3, np.interp(t3, t, y))
    assert skip["type"] == "skip" and "sample rate 5 Hz too low" in skip["reason"]


def test_gravity_left_in_the_channel_is_warned(healthy) -> None:  # type: ignore[no-untyped-def]
    t, y = healthy
    _, plain = _one(t, y)
    for g in (9.81, -9.81):
        _, line = _one(t, y + g)
        assert any(f"averages {g:+.3g} m/s^2" in w and "gravity not removed" in w
                   for w in line["warnings"])
        assert line["f_hz"] == pytest.approx(plain["f_hz"], rel=1e-9)


def test_an_invalid_marker_step_is_left_out(healthy) -> None:  # type: ignore[no-untyped-def]
    """-51.2 m/s^2 then 4 s of zeros inside the window (was: fitted as data, no warning)."""
    t, y = healthy
    bad = y.copy()
    bad[3000] = -51.2
    bad[3001:3400] = 0.0
    est, line = _one(t, bad)
    assert line["type"] == "estimate"
    (w,) = [w for w in line["warnings"] if "frozen" in w]
    assert w.startswith("400 samples of x1_ddot frozen at one value or an invalid marker "
                        "(t 30-33.99 s)")
    assert est.summary()["missing_samples"] == 400
    _, plain = _one(t, y)
    assert line["f_hz"] == pytest.approx(plain["f_hz"], rel=0.1)
    longer = y.copy()
    longer[1000:2000] = 0.0   # 10 s frozen: more than max_missing of the window
    _, skip = _one(t, longer)
    assert skip["type"] == "skip" and "frozen" in skip["reason"]


def test_missing_samples_in_warnings_and_summary_agree(quarter2) -> None:  # type: ignore[no-untyped-def]
    """Overlapping windows name the same gap; the summary counts each sample once."""
    s = damper_wear(quarter2, duration=120.0, fs=100.0, wear_start=119.0, c_end_fraction=1.0,
                    channels=("x1_ddot",), seed=4, chunk_s=0.5)
    y = np.asarray(s.data["x1_ddot"], dtype=float).copy()
    y[4000:4050] = np.nan   # t 40-40.49 s: in the windows 0-60, 30-90
    y[9000] = np.nan        # t 90 s: the end of 30-90 and in 60-120
    est = OutputOnlyEstimator("x1_ddot")
    out = []
    run_arrays(s.t, {"x1_ddot": y}, 60.0, 30.0, lambda t, d: out.append(est.process(t, d)))
    named = [int(w.split()[0]) for r in out for w in r.event.to_json().get("warnings", [])
             if "bridged" in w]
    assert not any(isinstance(r.event, Skip) for r in out)
    assert sorted(named) == [1, 50, 51]
    assert est.summary()["missing_samples"] == 51
