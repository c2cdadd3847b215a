"""Honest 3-sigma bands: unchanged where the cost is quadratic, the profile likelihood where
it is not, and a parameter the record does not bound is flagged, never reported as inside."""
from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.doe.design import experiments
from estimator.doe.runner import (JOINT_ALPHA, Outcome, Settings, band_coverage, free_names,
                                  joint_region, measurement, run_design, success_beyond)
from estimator.identify import OutputErrorProblem, Parameters, fit, jacobian_log
from estimator.identify.profile import R_TOL, SIGMAS, honest_bands
from estimator.identify.result import IdentResult
from suspid.models import get_model


def _noisy_fit(model: str, row: int, noise: float, cost: str = "sse"):
    m = get_model(model)
    e = experiments(m)[row - 1]
    meas, _ = measurement(m, e, noise, e.id)
    problem = OutputErrorProblem(m, meas, cost=cost, x0=e.x0)
    params = Parameters.for_model(m, fix={k: v for k, v in e.truth.items()
                                          if k not in free_names(m, False)},
                                  init={k: e.truth[k] for k in free_names(m, False)})
    res, _ = fit(problem, params, polish=True)
    return m, e, problem, params, res


def test_noise_free_band_is_the_curvature_band() -> None:
    """Noise-free record: the band is value +- 3 stderr, untouched, with no profile run."""
    m, e, problem, params, res = _noisy_fit("quarter2", 13, 0.0)
    b = honest_bands(problem, res, params.free)
    assert set(b.method.values()) == {"curvature"} and b.nfev == 0
    for k in params.free:
        lo, hi = b.bands[k]
        assert lo == pytest.approx(res.params[k] - SIGMAS * res.stderr[k], rel=1e-12)
        assert hi == pytest.approx(res.params[k] + SIGMAS * res.stderr[k], rel=1e-12)


def test_nearly_linear_band_is_kept_and_its_ends_are_3_sigma_points() -> None:
    """Low noise on a well-determined row: curvature band kept, and the check that kept it
    saw r^2 within 10 % of 9 at both ends."""
    m, e, problem, params, res = _noisy_fit("quarter2", 18, 0.1)
    b = honest_bands(problem, res, params.free)
    assert set(b.method.values()) == {"curvature"}
    for k in params.free:
        lo_ratio, hi_ratio = b.nonlinearity[k]
        assert abs(lo_ratio - 1) < 0.1 and abs(hi_ratio - 1) < 0.1, (k, b.nonlinearity[k])


def test_profile_band_end_is_where_the_refitted_cost_rises_by_9_sigma2() -> None:
    """Independent check of a profile end: fix the parameter there, refit the others with
    Nelder-Mead (not the profile's Levenberg-Marquardt), and the cost has risen by
    9 s_k^2 (r = 3) within a few per cent."""
    m, e, problem, params, res = _noisy_fit("half4", 10, 0.5)
    free = params.free
    b = honest_bands(problem, res, free)
    assert b.method["c2"] == "profile"
    i = free.index("c2")
    V = np.asarray(res.cov_log)
    J = jacobian_log(problem, res.params, free)
    G = np.linalg.pinv(J.T @ J)
    sk2 = V[i, i] / G[i, i]
    s0 = problem.normalized_ss(res.params) * problem.scale
    for end in b.bands["c2"]:
        p = params.copy()
        for k in free:
            p[k].value = res.params[k]
        p["c2"].value = end
        p["c2"].vary = False
        refit, _ = fit(problem, p, polish=True, with_stderr=False)
        r = math.sqrt((problem.normalized_ss(refit.params) * problem.scale - s0) / sk2)
        assert r == pytest.approx(SIGMAS, abs=0.1), (end, r)
    # the band is asymmetric, longer upwards (the cost is closer to quadratic in log(c2)),
    # and reaches the truth the curvature band (value + 3 stderr = 156.2) missed
    lo, hi = b.bands["c2"]
    assert hi - res.params["c2"] > res.params["c2"] - lo
    assert lo < e.truth["c2"] < hi < res.params["c2"] + 4 * res.stderr["c2"]


@pytest.mark.parametrize("model,noise,ids", [("quarter2", 0.5, [13, 22]), ("half4", 0.5, [10])])
def test_rows_outside_the_curvature_band_are_inside_the_honest_one_or_flagged(
        model: str, noise: float, ids: list[int]) -> None:
    """The rows whose truth lay outside value +- 3 stderr: now inside the reported band,
    or reported not identifiable with the parameter the record does not bound."""
    out = run_design(model, Settings(noise=noise), ids=ids)
    for e in out["experiments"]:
        flagged = not e["identifiable"] and any("does not bound" in w for w in e["warnings"])
        assert e["success"] or flagged, (e["id"], e["band_3sigma"], e["warnings"])
        assert any(v == "profile" for v in e["band_method"].values())
        for k, (lo, hi) in e["band_3sigma"].items():
            assert lo is not None and lo > 0, (k, lo)  # never below zero


def test_a_record_that_does_not_bound_a_parameter_is_flagged_with_the_reason() -> None:
    """quarter2 row 22 at 0.5 sigma: c1 and k1 can grow together without limit."""
    out = run_design("quarter2", Settings(noise=0.5), ids=[22])
    e = out["experiments"][0]
    assert e["identifiable"] is False and e["reported_success"] is False
    assert e["success"] is False  # an open band is not a success, whatever it contains
    assert e["band_3sigma"]["c1"][1] is None  # open above
    assert any("profile likelihood of c1" in w and "does not bound it" in w
               for w in e["warnings"])


def test_no_success_with_a_parameter_beyond_10x_on_a_small_far_noisy_design() -> None:
    """The identifier never reports success with a parameter more than 10x from the truth
    (rows that ran away at high noise and from far starts), and the design's summary lists
    no such row."""
    for scale, noise in ((0.1, 0.5), (10.0, 0.5)):
        m = get_model("quarter2")
        out = run_design(m, Settings(init_scale=scale, noise=noise), ids=[21, 22, 25])
        assert out["success_beyond_10x"] == []
        for e in out["experiments"]:
            far = [k for k, v in e["rel_error"].items() if not 0.1 <= 1 + v <= 10]
            assert not (e["reported_success"] and far), (scale, e["id"], far)
            assert not (e["success"] and far), (scale, e["id"], far)


def test_success_beyond_detects_a_far_success() -> None:
    """The summary's check is not vacuous: a success 20x off is listed, a failure is not."""
    far = Outcome(1, {"c": 1.0}, {"c": 20.0}, 19.0, True, {}, {}, 0, 0.0, 0.0, True,
                  {"rel_error": {"c": 19.0}, "reported_success": False})
    assert success_beyond(far, 10.0)
    far.success = False
    assert not success_beyond(far, 10.0)
    far.extra["reported_success"] = True
    assert success_beyond(far, 10.0)
    near = Outcome(2, {"c": 1.0}, {"c": 0.2}, 0.8, True, {}, {}, 0, 0.0, 0.0, True,
                   {"rel_error": {"c": -0.8}, "reported_success": True})
    assert not success_beyond(near, 10.0)


def test_every_profile_end_is_a_3_sigma_point_of_a_thorough_refit() -> None:
    """The profile refits stop at the accuracy the band needs (Gauss-Newton model agreement,
    also with a Broyden Jacobian; a cost within ``TOL_S s_k^2``) and the search's first step
    comes from the optimum's slope of ``r``: every closed end of every profile band is still
    a 3-sigma point within ``R_TOL`` when the others are refitted thoroughly (Nelder-Mead and
    scipy's Levenberg-Marquardt, started from the optimum). quarter2 row 9 at 0.5 sigma has
    long, flat profiles (k1 over a factor 20), where ``r`` is most sensitive to a refit
    stopped short."""
    m, e, problem, params, res = _noisy_fit("quarter2", 9, 0.5)
    free = params.free
    b = honest_bands(problem, res, free)
    profiled = [k for k in free if b.method[k] == "profile"]
    assert len(profiled) >= 2
    V = np.asarray(res.cov_log)
    J = jacobian_log(problem, res.params, free)
    G = np.linalg.pinv(J.T @ J)
    s0 = problem.normalized_ss(res.params) * problem.scale
    checked = 0
    for k in profiled:
        i = free.index(k)
        sk2 = V[i, i] / G[i, i]
        for end in b.bands[k]:
            if not 0 < end < math.inf:
                continue
            p = params.copy()
            for j in free:
                p[j].value = res.params[j]
            p[k].value = end
            p[k].vary = False
            refit, _ = fit(problem, p, polish=True, with_stderr=False)
            r = math.sqrt(max(problem.normalized_ss(refit.params) * problem.scale - s0, 0.0) / sk2)
            assert abs(r - SIGMAS) <= R_TOL + 0.005, (k, end, r)
            checked += 1
    assert checked >= 4


def _result(params: dict[str, float], cov: np.ndarray) -> IdentResult:
    return IdentResult(model="quarter2", params=params, fixed=[], stderr={k: 0.0 for k in params},
                       cost=0.0, nfev=0, success=True, rms_residual={}, identifiable=True,
                       cov_log=cov)


def test_the_joint_region_of_one_value_is_its_3_sigma_band() -> None:
    """One free value: the region is the curvature band itself (chi2_1 quantile 9)."""
    res = _result({"c1": 1000.0}, np.array([[0.01 ** 2]]))  # 1 % standard error in log
    inside = joint_region(res, {"c1": 1000.0 * math.exp(2.99 * 0.01)}, ["c1"])
    outside = joint_region(res, {"c1": 1000.0 * math.exp(-3.01 * 0.01)}, ["c1"])
    assert inside is not None and outside is not None
    assert inside["limit"] == pytest.approx(9.0, rel=1e-9) and inside["dof"] == 1
    assert inside["inside"] and not outside["inside"]
    assert outside["d2"] == pytest.approx(3.01 ** 2, rel=1e-9)


def test_the_joint_region_uses_the_correlations() -> None:
    """Two values each 2.5 sigma off (inside both bands) along the direction the covariance
    makes unlikely lie outside the joint region; along the likely one they lie inside."""
    sd, rho = 0.01, 0.95
    cov = sd ** 2 * np.array([[1.0, rho], [rho, 1.0]])
    res = _result({"k1": 1e4, "k2": 1e5}, cov)
    against = {"k1": 1e4 * math.exp(2.5 * sd), "k2": 1e5 * math.exp(-2.5 * sd)}
    along = {"k1": 1e4 * math.exp(2.5 * sd), "k2": 1e5 * math.exp(2.5 * sd)}
    a = joint_region(res, against, ["k1", "k2"])
    b = joint_region(res, along, ["k1", "k2"])
    assert a is not None and b is not None
    assert not a["inside"] and b["inside"]
    assert a["limit"] == pytest.approx(-2.0 * math.log(JOINT_ALPHA), rel=1e-9)  # chi2_2


def test_noisy_design_reports_the_joint_region_per_row_and_in_total() -> None:
    out = run_design("quarter2", Settings(noise=0.5), ids=[1, 24])
    rows = {e["id"]: e for e in out["experiments"]}
    assert out["in_joint_region"] == sum(e["joint_3sigma"]["inside"] for e in rows.values())
    # row 24 misses its per-parameter bands by a value ~3 sigma off; jointly it is a
    # 4 % event (d2 about 10 for 4 values), inside the region
    assert rows[24]["success"] is False and rows[24]["joint_3sigma"]["inside"] is True
    assert "in_joint_region" not in run_design("quarter2", Settings(), ids=[1])


def test_band_coverage_counts_closed_bands_and_their_misses() -> None:
    """One miss in 3 closed bands (an open band of a flagged row not counted), one row of two
    outside its joint region: the expected counts and the binomial tail of the rows."""
    rows = [{"id": 1, "true": {"c1": 1.0, "k1": 2.0},
             "band_3sigma": {"c1": [0.9, 1.1], "k1": [2.1, 2.3]},       # k1 missed
             "joint_3sigma": {"inside": False}},
            {"id": 2, "true": {"c1": 1.0, "k1": 2.0},
             "band_3sigma": {"c1": [0.5, 1.5], "k1": [1.0, None]},      # k1 open: not counted
             "joint_3sigma": {"inside": True}}]
    b = band_coverage(rows)
    assert b["bands"] == 3 and b["missed"] == 1 and b["rows_missed"] == [1]
    assert b["expected"] == pytest.approx(3 * JOINT_ALPHA, abs=1e-4)
    assert b["joint_rows"] == 2 and b["joint_outside"] == [1]
    assert b["p_value"] == pytest.approx(1 - (1 - JOINT_ALPHA) ** 2, rel=1e-9)
    clean = band_coverage(rows[1:])
    assert clean["missed"] == 0 and clean["joint_outside"] == [] and clean["p_value"] == 1.0


def test_noisy_design_reports_its_band_coverage() -> None:
    """quarter2 rows 1 and 24 at 0.5 sigma: row 24's miss is counted among 8 closed bands,
    and it lies inside its joint region."""
    out = run_design("quarter2", Settings(noise=0.5), ids=[1, 24])
    b = out["band_coverage"]
    rows = {e["id"]: e for e in out["experiments"]}
    assert b["rows_missed"] == [24] and rows[24]["success"] is False
    assert b["bands"] == 8 and b["missed"] >= 1
    assert b["joint_rows"] == 2 and b["joint_outside"] == []
    assert "band_coverage" not in run_design("quarter2", Settings(), ids=[1])
