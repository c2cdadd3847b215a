"""A record with a constant offset (a sensor zero not at rest): found, named and removed.

The records are ``suspid simulate`` bumps at 1 % noise with a constant added to a road
column or a position channel afterwards. Before the offset check ``identify`` spent 22,598
evaluations (204 s) on the quarter-car road offset below and warned of unidentifiable
combinations instead of the offset.
"""
from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from estimator.identify import OutputErrorProblem, estimate_start
from estimator.identify.offset import OFFSET_SHARE, Offset, find_offset
from estimator.identify.params import Parameters
from suspid.cli import main
from suspid.io.csvio import read_measurement
from suspid.models import get_model

#: the quarter car's defaults (the truth of the records)
Q2 = {"m1": 300.0, "c1": 1500.0, "k1": 20000.0, "m2": 40.0, "c2": 300.0, "k2": 200000.0}


def _shifted(src: Path, dst: Path, column: str, d: float) -> Path:
    """``src`` with ``d`` added to ``column``, written to ``dst``."""
    with src.open(newline="") as f:
        rows = list(csv.DictReader(f))
    with dst.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for row in rows:
            row[column] = repr(float(row[column]) + d)
            w.writerow(row)
    return dst


@pytest.fixture(scope="module")
def records(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("offset")
    out: dict[str, Path] = {}
    for name, model, extra in (("q2", "quarter2", []), ("h4", "half4", []),
                               ("q2_friction", "quarter2", ["--effect", "coulomb_friction:F=120"])):
        out[name] = d / f"{name}.csv"
        assert main(["simulate", "--model", model, "--scenario", "bump", "--noise", "0.01",
                     "--seed", "1", "--out", str(out[name]), *extra]) == 0
    out["q2_r"] = _shifted(out["q2"], d / "q2_r.csv", "r", 0.01)
    out["q2_x1"] = _shifted(out["q2"], d / "q2_x1.csv", "x1", 0.004)
    out["h4_r1"] = _shifted(out["h4"], d / "h4_r1.csv", "r1", 0.01)
    return out


def _found(path: Path, model_name: str, fix: dict[str, float]) -> Offset | None:
    """:func:`find_offset` at the data-driven start of ``path``."""
    model = get_model(model_name)
    problem = OutputErrorProblem(model, read_measurement(path, model))
    params = Parameters.for_model(model, fix=fix)
    est = estimate_start(problem, params)
    return find_offset(problem, {**params.valuesdict(), **est.values})


def test_identify_names_and_removes_a_road_offset(records: dict[str, Path],
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """One warning line names the column, the offset in m and the remedy; the fit is the
    clean record's, at the clean record's cost in evaluations (699 there; 22,598 before)."""
    assert main(["identify", "--model", "quarter2", "--input", str(records["q2_r"]),
                 "--fix", "m1=300", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    first = out["warnings"][0]
    assert first.startswith("offset: road column r reads +0.01 m") and "--offset keep" in first
    assert not any("unidentifiable" in w or "implausible" in w for w in out["warnings"])
    assert out["offset"]["kind"] == "road" and out["offset"]["removed"] is True
    assert out["offset"]["values"]["r"] == pytest.approx(0.01, abs=1e-4)
    assert out["offset"]["effects"] == ["sensor_offset:channel=r,offset=0.0100024"]
    assert out["nfev"] <= 1500
    assert out["success"] is True
    for k in ("c1", "k1", "k2"):
        assert out["params"][k] == pytest.approx(Q2[k], rel=0.01)


def test_a_position_channel_offset_is_named(records: dict[str, Path]) -> None:
    """An offset on one position channel is that channel's, not the road's."""
    off = _found(records["q2_x1"], "quarter2", {"m1": 300.0})
    assert off is not None and off.kind == "channel" and list(off.values) == ["x1"]
    assert off.values["x1"] == pytest.approx(0.004, abs=1e-4)
    assert "position channel x1 reads +0.004 m" in off.warning(get_model("quarter2"), False)


def test_half_car_offset_on_one_road(records: dict[str, Path]) -> None:
    """Each road column gets its own offset: r1's, and about none on r2."""
    off = _found(records["h4_r1"], "half4", {"m": 1200.0})
    assert off is not None and off.kind == "road"
    assert off.values["r1"] == pytest.approx(0.01, abs=2e-4)
    assert list(off.values) == ["r1"]  # r2 reads no offset the record resolves
    assert off.share < OFFSET_SHARE


@pytest.mark.parametrize("name, model, fix", [("q2", "quarter2", {"m1": 300.0}),
                                              ("h4", "half4", {"m": 1200.0}),
                                              ("q2_friction", "quarter2", {"m1": 300.0})])
def test_no_offset_where_there_is_none(records: dict[str, Path], name: str, model: str,
                                       fix: dict[str, float]) -> None:
    """Clean records, and a misfit of another kind (dry friction), report no offset."""
    assert _found(records[name], model, fix) is None
