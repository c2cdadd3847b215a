"""A fit the model cannot follow (wrong ``--fix`` values) is no success, and costs no more
than a normal fit's time."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from estimator.identify import OutputErrorProblem, Parameters, fit
from estimator.identify.inputs import read_input
from estimator.identify.misfit import MISFIT_FLOOR, MISFIT_SHARE, misfit_channels
from suspid.cli import main
from suspid.models import get_model


def _simulate(tmp_path: Path, model: str, noise: float, capsys: pytest.CaptureFixture[str],
              duration: str = "2") -> Path:
    csv = tmp_path / f"{model}_{noise}.csv"
    assert main(["simulate", "--model", model, "--scenario", "bump", "--duration", duration,
                 "--fs", "200", "--noise", str(noise), "--seed", "3", "--out", str(csv)]) == 0
    capsys.readouterr()
    return csv


def _identify(capsys: pytest.CaptureFixture[str], *argv: str) -> dict:
    assert main(["identify", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("noise", [0.0, 0.1])
def test_every_value_fixed_twice_the_truth_is_no_success(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], noise: float) -> None:
    """Nothing free, the springs and dampers held at twice the truth: the residual is far
    above the noise floor (noise-free: far above nothing), so the fit is no success and a
    warning names the channel and the held values; held at the truth it is a success."""
    csv = _simulate(tmp_path, "quarter2", noise, capsys)
    wrong = _identify(capsys, "--model", "quarter2", "--input", str(csv), "--fix", "m1=300",
                      "--fix", "m2=40", "--fix", "c1=3000", "--fix", "k1=40000",
                      "--fix", "c2=600", "--fix", "k2=400000")
    assert wrong["success"] is False
    (warning,) = [w for w in wrong["warnings"] if w.startswith("misfit:")]
    assert "x1 (noise-floor ratio" in warning and "c1=3000" in warning and "--fix" in warning
    right = _identify(capsys, "--model", "quarter2", "--input", str(csv), "--fix", "m1=300",
                      "--fix", "m2=40", "--fix", "c1=1500", "--fix", "k1=20000",
                      "--fix", "c2=300", "--fix", "k2=200000")
    assert right["success"] is True
    assert not any(w.startswith("misfit:") for w in right["warnings"])


def test_misfit_channels_need_a_ratio_and_a_share(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """At the truth no channel is a misfit, noisy or noise-free (where the ratio compares
    rounding errors); twice the springs are, on both."""
    model = get_model("quarter2")
    truth = model.defaults()
    wrong = {**truth, "k1": 2 * truth["k1"], "k2": 2 * truth["k2"]}
    for noise in (0.0, 0.1):
        meas, _ = read_input(str(_simulate(tmp_path, "quarter2", noise, capsys)), model)
        problem = OutputErrorProblem(model, meas)
        assert misfit_channels(problem, truth) == {}, noise
        bad = misfit_channels(problem, wrong)
        assert "x1" in bad, noise
        assert all(r > MISFIT_FLOOR and sh > MISFIT_SHARE for r, sh in bad.values())


@pytest.mark.slow
def test_a_length_in_mm_ends_in_a_normal_fit_time_as_a_misfit(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--fix a1=1200`` (mm for m) on the half car with no ``--maxfev``: the further
    starts of each fit stop once one returns to the best cost (each used to spend its own
    full budget: 21806 evaluations), the unit slip is named and the fit is no success."""
    csv = _simulate(tmp_path, "half4", 0.0, capsys, duration="1")
    out = _identify(capsys, "--model", "half4", "--input", str(csv), "--fix", "m=1200",
                    "--fix", "I=1500", "--fix", "m1=40", "--fix", "m2=40", "--fix", "a2=1.4",
                    "--fix", "a1=1200")
    assert out["nfev"] < 8000
    assert out["success"] is False
    assert any("outside 0.01..20 m" in w for w in out["warnings"])
    assert any(w.startswith("misfit:") and "a1=1200" in w for w in out["warnings"])


def test_a_further_start_back_at_the_best_cost_ends_the_search(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A fit whose parameters run far from a far-off start triggers further starts; the
    first that returns to the same cost ends them (every one used to run: 1090 evaluations
    where 441 now reach the same fit)."""
    model = get_model("quarter1")
    meas, _ = read_input(str(_simulate(tmp_path, "quarter1", 0.0, capsys)), model)
    problem = OutputErrorProblem(model, meas)
    params = Parameters.for_model(model, fix={"m": 300.0}, init={"c": 15.0, "k": 200.0})
    res, out = fit(problem, params, multistart=4, polish=True)
    assert res.success and res.params["k"] == pytest.approx(20000.0, rel=1e-6)
    assert out.nfev < 700
