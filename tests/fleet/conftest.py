"""A small synthetic fleet with known wear, and a runner of ``suspid fleet``.

Three vehicles, six 8 s drives each over 40 days: ``VAN-WORN`` (damper -1 %/day, below the
70 % limit from day 30: an alert), ``VAN-WEAR`` (-0.5 %/day, crosses on day 60: a forecast),
``VAN-OK`` (no wear; one drive as BLF and one as CSV, plus a garbage log and a truncated
one that must fail without stopping the batch).
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from tools.synthetic_fleet import EPOCH0, FleetSpec, VehicleWear, make_fleet, write_drive
from suspid.can.dbc import load_dbc
from tests.conftest import REPO, suspid_env

FIX = ["--fix", "m1=300", "--fix", "m2=40"]
TIMEOUT = 600


@dataclass
class Fleet:
    root: Path
    spec: FleetSpec
    truth: list[dict[str, Any]]
    bad: list[Path]

    def vehicle(self, name: str) -> VehicleWear:
        return next(v for v in self.spec.vehicles if v.name == name)


def run_fleet_cli(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    """``python -m suspid fleet ARGS`` in a subprocess (this checkout)."""
    proc = subprocess.run([sys.executable, "-m", "suspid", "fleet", *args], capture_output=True,
                          text=True, env=suspid_env(), cwd=REPO, timeout=TIMEOUT)
    if check and proc.returncode != 0:
        raise AssertionError(f"suspid fleet {' '.join(args)} exited {proc.returncode}: "
                             f"{proc.stderr[-3000:]}")
    return proc


def fleet_json(*args: str) -> dict[str, Any]:
    return json.loads(run_fleet_cli(*args, "--json").stdout)


@pytest.fixture(scope="session")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Fleet:
    root = tmp_path_factory.mktemp("fleet") / "logs"
    spec = FleetSpec([VehicleWear("VAN-WORN", c1_rate=0.010), VehicleWear("VAN-WEAR", c1_rate=0.005),
                      VehicleWear("VAN-OK")], drives=18, days=40.0, duration=8.0, fs=200.0)
    truth = make_fleet(root, spec)
    db = load_dbc(None)
    ok = spec.vehicles[2]
    for fmt, day in ((".blf", 42.0), (".csv", 44.0)):
        s2 = FleetSpec(spec.vehicles, duration=8.0, fs=200.0, fmt=fmt)
        path = root / ok.name / f"extra{fmt}"
        t0 = EPOCH0 + day * 86400.0
        p = write_drive(path, s2, ok, t0, seed=77 + int(day), db=db)
        truth.append({"path": str(path), "vehicle": ok.name, "t": t0, "params": p})
    garbage = root / ok.name / "garbage.log"
    garbage.write_text("this is not a candump log\n")
    truncated = root / ok.name / "truncated.blf"
    shutil.copy(root / ok.name / "extra.blf", truncated)
    with open(truncated, "r+b") as fh:
        fh.truncate(300)
    (root / ok.name / "notes.txt").write_text("not a drive: ignored by discovery\n")
    return Fleet(root, spec, truth, [garbage, truncated])


@pytest.fixture(scope="session")
def inprocess(fleet: Fleet) -> dict[str, Any]:
    """The fleet identified in the client process (``--workers 0``)."""
    return fleet_json("--model", "quarter2", "--input", str(fleet.root), *FIX, "--workers", "0")


@dataclass
class HistoryRuns:
    db: Path
    first: dict[str, Any]      # VAN-WEAR alone into a new database
    second: dict[str, Any]     # then the whole fleet
    third: dict[str, Any]      # then a renamed copy of one VAN-WEAR log
    copy: Path


@pytest.fixture(scope="session")
def history(fleet: Fleet, tmp_path_factory: pytest.TempPathFactory) -> HistoryRuns:
    """Three runs into one ``--db``: one vehicle, the fleet, a renamed copy of a log."""
    base = tmp_path_factory.mktemp("history")
    db = base / "hist" / "fleet.sqlite"
    common = ["--model", "quarter2", *FIX, "--workers", "0", "--db", str(db)]
    first = fleet_json("--input", str(fleet.root / "VAN-WEAR"), *common)
    second = fleet_json("--input", str(fleet.root), *common)
    copy = base / "again" / "VAN-WEAR" / "same-drive-renamed.log"
    copy.parent.mkdir(parents=True)
    shutil.copy(fleet.truth[1]["path"], copy)
    third = fleet_json("--input", str(copy.parent), *common)
    return HistoryRuns(db, first, second, third, copy)
