"""``suspid fleet``: the contract's JSON, identity with ``suspid identify``, failed logs."""
from __future__ import annotations

import json
import subprocess
import sys
from typing import Any

import pytest

from tests.conftest import REPO, suspid_env
from tests.fleet.conftest import FIX, TIMEOUT, Fleet, run_fleet_cli


@pytest.mark.slow
def test_contract_fields_and_failed_logs(fleet: Fleet, inprocess: dict[str, Any]) -> None:
    out = inprocess
    assert set(out) >= {"drives", "vehicles", "failed"}
    assert len(out["drives"]) == len(fleet.truth) + len(fleet.bad)   # notes.txt not a drive
    for d in out["drives"]:
        assert set(d) >= {"path", "vehicle", "t", "params", "stderr", "status", "error"}
        assert d["status"] in ("ok", "failed")
    truth = {t["path"]: t for t in fleet.truth}
    for d in out["drives"]:
        if d["path"] in truth:
            assert d["status"] == "ok", d["error"]
            assert d["error"] is None
            assert d["vehicle"] == truth[d["path"]]["vehicle"]
            assert abs(d["t"] - truth[d["path"]]["t"]) < 1e-6     # first frame's time, epoch s
            assert set(d["params"]) == {"m1", "c1", "k1", "m2", "c2", "k2"}
            assert set(d["stderr"]) == {"c1", "k1", "c2", "k2"}
            assert abs(d["params"]["c1"] / truth[d["path"]]["params"]["c1"] - 1) < 0.02
    failed = {d["path"]: d for d in out["drives"] if d["status"] == "failed"}
    assert set(failed) == {str(p) for p in fleet.bad}
    assert out["failed"] == 2
    for path, d in failed.items():
        assert d["params"] is None and d["vehicle"] == "VAN-OK"
        assert path in d["error"] and "\n" not in d["error"]
    vehicles = {v["vehicle"]: v for v in out["vehicles"]}
    assert set(vehicles) == {"VAN-WORN", "VAN-WEAR", "VAN-OK"}
    for v in out["vehicles"]:
        assert set(v) >= {"vehicle", "drives", "latest", "trend", "alerts", "forecast"}
        assert set(v["trend"]) == {"c1", "k1", "c2", "k2"}          # the free parameters
        assert v["warnings"] == []                  # every drive dated, each at its own time
        for tr in v["trend"].values():
            assert set(tr) >= {"rate_per_day", "stderr"}
    assert vehicles["VAN-OK"]["drives"] == 8
    last_ok = max((d for d in out["drives"] if d["vehicle"] == "VAN-OK" and d["status"] == "ok"),
                  key=lambda d: d["t"])
    assert vehicles["VAN-OK"]["latest"] == last_ok["params"]


@pytest.mark.slow
def test_progress_bar_and_bad_usage(fleet: Fleet) -> None:
    proc = run_fleet_cli("--model", "quarter2", "--input", str(fleet.root / "VAN-OK" / "extra.csv"),
                         *FIX, "--workers", "0", "--json")
    assert "1/1 drives" in proc.stderr and "[" in proc.stderr
    assert json.loads(proc.stdout)["failed"] == 0
    for args, words in ((["--input", str(fleet.root)], "--model"),
                        (["--model", "quarter2", "--input", str(fleet.root / "nope")], "nope"),
                        (["--model", "quarter2", "--input", str(fleet.root), "--fix", "zz=1"], "zz"),
                        (["--db", str(fleet.root / "none.sqlite")], "none.sqlite")):
        proc = run_fleet_cli(*args, "--workers", "0", "--json", check=False)
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error:") and words in lines[0], proc.stderr


@pytest.mark.slow
def test_each_drive_equals_suspid_identify(fleet: Fleet, inprocess: dict[str, Any]) -> None:
    """Same parameters to the last digit (and stderr, cost, warnings, frame counts) as
    ``suspid identify --json`` on the same file with the same options: candump, BLF, CSV."""
    drives = {d["path"]: d for d in inprocess["drives"]}
    picks = [fleet.truth[0]["path"], fleet.truth[-2]["path"], fleet.truth[-1]["path"]]
    assert [p.rsplit(".", 1)[1] for p in picks] == ["log", "blf", "csv"]
    for path in picks:
        proc = subprocess.run([sys.executable, "-m", "suspid", "identify", "--model", "quarter2",
                               "--input", path, *FIX, "--json"], capture_output=True, text=True,
                              env=suspid_env(), cwd=REPO, timeout=TIMEOUT)
        assert proc.returncode == 0, proc.stderr
        ref = json.loads(proc.stdout)
        d = drives[path]
        for k in ("params", "stderr", "cost", "nfev", "fixed", "rms_residual", "warnings",
                  "identifiable", "success"):
            assert d[k] == ref[k], (path, k)
        assert d.get("frames") == ref.get("frames")
