"""The production sensor set over CAN: body accelerations and ride heights encoded as the
node sends them (quantized by the DBC), decoded and identified with the road unknown."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import REPO, suspid_env


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "suspid", *args], capture_output=True, text=True,
                          env=suspid_env(), cwd=REPO, timeout=300)


@pytest.mark.parametrize("model,fix,struts", [
    ("quarter2", ["m1=300", "m2=40"], {"c1": 1500.0, "k1": 20000.0}),
    ("half4", ["m=1200", "I=1500", "m1=40", "m2=40", "a1=1.2", "a2=1.4"],
     {"c1": 2000.0, "k1": 30000.0, "c2": 2000.0, "k2": 30000.0}),
])
def test_production_log_identifies_struts(tmp_path: Path, model: str, fix: list[str],
                                          struts: dict[str, float]) -> None:
    csv, log = tmp_path / "drive.csv", tmp_path / "drive.log"
    p = _run("simulate", "--model", model, "--scenario", "iso8608", "--duration", "20",
             "--fs", "500", "--noise", "0.02", "--channels", "production", "--seed", "4",
             "--out", str(csv))
    assert p.returncode == 0, p.stderr
    assert "r" not in csv.read_text().splitlines()[0].split(",")
    p = _run("encode", "--input", str(csv), "--out", str(log))
    assert p.returncode == 0, p.stderr
    p = _run("identify", "--model", model, "--input", str(log),
             *[a for f in fix for a in ("--fix", f)], "--json")
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["road"] == "unknown" and out["frames"]["accepted"] > 0
    for name, truth in struts.items():
        assert abs(out["params"][name] / truth - 1) < 0.01, (name, out["params"][name])
        assert out["stderr"][name] > 0
