"""``suspid fleet`` checks each drive for a constant road or position offset as identify does.

A vehicle with a clean bump drive and the same drive with its road column 0.01 m off (a
road sensor zeroed 1 cm from the rest position). Before, fleet fitted the offset drive as
it was: no warning naming the offset and no ``offset`` field (identify's fit of this record
as it is: 22,598 evaluations, ``success: false``, docs/robustness.md).
"""
from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import pytest

from estimator.fleet.drive import IdentifySettings
from suspid.cli import main
from tests.fleet.conftest import FIX, fleet_json

#: the quarter car's defaults (the truth of ``suspid simulate``'s records)
Q2 = {"m1": 300.0, "c1": 1500.0, "k1": 20000.0, "m2": 40.0, "c2": 300.0, "k2": 200000.0}
ROAD_OFFSET = 0.01


@pytest.fixture(scope="module")
def drives(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("offset-fleet") / "logs"
    van = root / "VAN-ZERO"
    van.mkdir(parents=True)
    clean = van / "clean.csv"
    assert main(["simulate", "--model", "quarter2", "--scenario", "bump", "--noise", "0.01",
                 "--seed", "1", "--out", str(clean)]) == 0
    with clean.open(newline="") as f:
        rows = list(csv.DictReader(f))
    shifted = van / "road-offset.csv"
    with shifted.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for row in rows:
            w.writerow({**row, "r": repr(float(row["r"]) + ROAD_OFFSET)})
    return {"root": root, "clean": clean, "offset": shifted}


@pytest.fixture(scope="module")
def run(drives: dict[str, Path]) -> dict[str, Any]:
    return fleet_json("--model", "quarter2", "--input", str(drives["root"]), *FIX,
                      "--workers", "0", "--no-progress")


def test_drive_with_a_road_offset(drives: dict[str, Path], run: dict[str, Any],
                                  capsys: pytest.CaptureFixture[str]) -> None:
    by_path = {d["path"]: d for d in run["drives"]}
    d = by_path[str(drives["offset"])]
    assert d["status"] == "ok", d["error"]
    assert d["warnings"][0].startswith("offset: road column r reads +0.01 m")
    assert d["offset"]["kind"] == "road" and d["offset"]["removed"] is True
    assert d["offset"]["values"]["r"] == pytest.approx(ROAD_OFFSET, abs=1e-4)
    for k in ("c1", "k1", "k2"):
        assert d["params"][k] == pytest.approx(Q2[k], rel=0.01)
    assert d["params"]["c2"] == pytest.approx(Q2["c2"], rel=0.1)   # the tyre's damping, weakly seen
    # the same identification as identify's on the same file
    assert main(["identify", "--model", "quarter2", "--input", str(drives["offset"]), *FIX,
                 "--json"]) == 0
    ident = json.loads(capsys.readouterr().out)
    assert ident["offset"] == d["offset"] and ident["params"] == d["params"]
    clean = by_path[str(drives["clean"])]
    assert clean["status"] == "ok" and "offset" not in clean
    assert not any(w.startswith("offset:") for w in clean.get("warnings", []))


def test_offset_mode_is_part_of_the_settings_key() -> None:
    """A history written with one --offset mode is stale for the other."""
    remove, keep = IdentifySettings("quarter2"), IdentifySettings("quarter2", offset="keep")
    assert remove.offset == "remove"
    assert json.loads(remove.key())["offset"] == "remove"
    assert remove.key() != keep.key()
