"""Poor records: too few samples for the unknowns, missing runs of a measured channel.

A record with no more measured values than the fit has unknowns (free parameters and the
initial states it estimates) is fitted exactly by a continuum of parameter values: it must
not be reported as a success with standard errors. A run of missing samples in a measured
channel is named in the warnings, as a road column's is.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from estimator.identify import OutputErrorProblem, Parameters
from estimator.identify.identifiability import assess
from estimator.identify.record import identify_record
from estimator.identify.solver import too_little_data
from suspid.errors import InputError
from suspid.cli import main
from suspid.io.csvio import read_measurement
from suspid.models import get_model

from ..conftest import REPO, suspid_env


def _bump(tmp_path: Path) -> Path:
    """The quarter car's default bump record (500 Hz, 3 s) as a CSV."""
    path = tmp_path / "bump.csv"
    assert main(["simulate", "--model", "quarter2", "--scenario", "bump", "--fs", "500",
                 "--out", str(path)]) == 0
    return path


def _rows(src: Path, dst: Path, first: int, count: int) -> Path:
    lines = src.read_text().splitlines()
    dst.write_text("\n".join([lines[0]] + lines[1 + first:1 + first + count]) + "\n")
    return dst


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "suspid", *args], capture_output=True,
                          text=True, env=suspid_env(), cwd=REPO, timeout=120)


def _no_success(path: Path) -> dict:
    """``identify`` of ``path`` (quarter2, m1 held): exit 0, neither a success nor
    identifiable, no standard error and no band; its JSON."""
    proc = _run("identify", "--model", "quarter2", "--input", str(path), "--fix", "m1=300",
                "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["success"] is False and out["identifiable"] is False
    assert all(v is None for v in out["stderr"].values())
    assert "band_3sigma" not in out
    return dict(out)


def test_two_row_csv_is_no_success(tmp_path: Path) -> None:
    """2 rows of a moving record: 4 values in the cost for 5 parameters + 4 initial states
    (was: success, identifiable, stderr ~1e-3 and a 3-sigma band)."""
    two = _rows(_bump(tmp_path), tmp_path / "two.csv", 300, 2)
    out = _no_success(two)
    assert out["warnings"][0].startswith("too little data: 4 measured values in the cost "
                                         "(2 samples of x1, x2) for 9 unknowns")


def test_too_little_data_counts_states_and_channels(tmp_path: Path) -> None:
    """The threshold comes from the record: values in the cost against free parameters
    plus estimated initial states; fixing the start or parameters lowers it."""
    model = get_model("quarter2")
    meas = read_measurement(_rows(_bump(tmp_path), tmp_path / "five.csv", 300, 5), model)
    est = OutputErrorProblem(model, meas)  # sse: x1, x2 -> 10 values
    assert est.n_obs == 10
    assert too_little_data(est, 5) is None          # 10 > 5 + 4
    assert too_little_data(est, 5, 1) is not None   # 10 = 5 + 4 + 1 offset
    assert too_little_data(est, 6) is not None
    rest = OutputErrorProblem(model, meas, x0="rest")
    assert too_little_data(rest, 6) is None         # no initial state estimated
    assert too_little_data(rest, 0) is None


@pytest.mark.slow
def test_one_sample_can_log_is_no_success(tmp_path: Path) -> None:
    """A candump log holding one sample's frames (was: success, stderr 1e-5, a band of
    zero width)."""
    two = _rows(_bump(tmp_path), tmp_path / "two.csv", 300, 2)
    log = tmp_path / "two.log"
    assert _run("encode", "--input", str(two), "--out", str(log)).returncode == 0
    one = tmp_path / "one.log"
    one.write_text("\n".join(log.read_text().splitlines()[:5]) + "\n")
    out = _no_success(one)
    assert any(w.startswith("too little data") for w in out["warnings"])


def test_identify_record_removes_no_offset_from_too_few_values(tmp_path: Path) -> None:
    model = get_model("quarter2")
    meas = read_measurement(_rows(_bump(tmp_path), tmp_path / "two.csv", 300, 2), model)
    params = Parameters.for_model(model, fix={"m1": 300.0}, init={})
    res, fitted = identify_record(OutputErrorProblem(model, meas), params, restarts=1,
                                  multistart=0)
    assert res.offset is None and fitted.meas is meas
    assert not res.success and not res.identifiable


def test_fewer_rows_than_parameters_is_rank_deficient() -> None:
    """An SVD of an M x n matrix with M < n reports M singular values: the missing ones
    are zeros (was: a 4 x 5 sensitivity matrix judged identifiable)."""
    rng = np.random.default_rng(0)
    verdict = assess(rng.normal(size=(4, 5)), ["a", "b", "c", "d", "e"], {})
    assert not verdict.identifiable
    assert len(verdict.singular_values) == 5 and verdict.singular_values[-1] == 0.0
    assert assess(rng.normal(size=(6, 5)), ["a", "b", "c", "d", "e"], {}).identifiable


def test_a_missing_run_of_a_measured_channel_is_named(tmp_path: Path) -> None:
    """100 samples of x1 NaN and 3 empty cells (was: exit 0, no warning)."""
    src = _bump(tmp_path).read_text().splitlines()
    i = src[0].split(",").index("x1")
    rows = [r.split(",") for r in src[1:]]
    for k in range(500, 600):
        rows[k][i] = "nan"
    for k in range(1000, 1003):
        rows[k][i] = ""
    path = tmp_path / "gap.csv"
    path.write_text("\n".join([src[0]] + [",".join(r) for r in rows]) + "\n")
    meas = read_measurement(path, get_model("quarter2"))
    msg = [w for w in meas.warnings if "'x1'" in w]
    assert msg == [f"{path}: column 'x1': 103 missing samples in 2 runs: 100 at t 1-1.198 s, "
                   "3 at t 2-2.004 s; not compared there"]
    assert not any("'x2'" in w for w in meas.warnings)


def test_many_runs_are_counted_beyond_the_first_five(tmp_path: Path) -> None:
    src = _bump(tmp_path).read_text().splitlines()
    rows = [r.split(",") for r in src[1:]]
    i = src[0].split(",").index("x2")
    for k in range(100, 1000, 100):
        rows[k][i] = ""
    path = tmp_path / "many.csv"
    path.write_text("\n".join([src[0]] + [",".join(r) for r in rows]) + "\n")
    (msg,) = [w for w in read_measurement(path, get_model("quarter2")).warnings if "'x2'" in w]
    assert "9 missing samples in 9 runs: 1 at t 0.2 s," in msg and "and 4 more runs" in msg


@pytest.mark.parametrize("cell, says", [("nan", "is 'nan'"), ("", "is empty")])
def test_a_nan_time_names_its_row(tmp_path: Path, cell: str, says: str) -> None:
    src = _bump(tmp_path).read_text().splitlines()
    rows = [r.split(",") for r in src[1:]]
    rows[49][0] = cell
    path = tmp_path / "t.csv"
    path.write_text("\n".join([src[0]] + [",".join(r) for r in rows]) + "\n")
    with pytest.raises(InputError, match=rf"t.csv:51: column 't' {says} \(data row 50\), "
                                         "expected a time in s"):
        read_measurement(path, get_model("quarter2"))


def test_all_measured_columns_empty_says_so(tmp_path: Path) -> None:
    """(was: "no measured channel", as if the columns were not there)"""
    src = _bump(tmp_path).read_text().splitlines()
    head = src[0].split(",")
    keep = [j for j, h in enumerate(head) if h in ("t", "r", "r_dot")]
    rows = [[c if j in keep else "NaN" for j, c in enumerate(r.split(","))] for r in src[1:]]
    path = tmp_path / "empty.csv"
    path.write_text("\n".join([src[0]] + [",".join(r) for r in rows]) + "\n")
    with pytest.raises(InputError, match=r"every measured column is empty \(x1, x2, x1_dot, "
                                         rf"x2_dot: no value in {len(rows)} rows\)"):
        read_measurement(path, get_model("quarter2"))


def test_measurement_gaps_reach_monitor_summary(tmp_path: Path) -> None:
    src = _bump(tmp_path).read_text().splitlines()
    i = src[0].split(",").index("x1")
    rows = [r.split(",") for r in src[1:]]
    for k in range(500, 600):
        rows[k][i] = "nan"
    path = tmp_path / "gap.csv"
    path.write_text("\n".join([src[0]] + [",".join(r) for r in rows]) + "\n")
    proc = _run("monitor", "--model", "quarter2", "--input", str(path), "--fix", "m1=300",
                "--window", "1", "--step", "1", "--jsonl")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout.splitlines()[-1])
    assert any("column 'x1': 100 missing samples at t 1-1.198 s" in w
               for w in summary["warnings"]), summary["warnings"]
