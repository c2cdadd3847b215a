"""The EKF baseline across a gap in the data: it restarts the motion, not one short step.

A dead link (frames missing from a log) or rows missing from a CSV leave 0.5 s without data.
The sliding window skips or refits the windows around it from a fresh initial state; the
EKF predicted the gap as one sample step (CSV: a NIS of ~650 and a false damper alert) or
through an interpolated road (log: one window inconsistent). It now restarts its motion
states after the gap and carries its parameters over the elapsed time.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from estimator.ekf.stream import EKFWindowEstimator
from estimator.ekf.stream import BRIDGE_SAMPLES
from estimator.stream.wear_streams import damper_wear, write_log
from suspid.io.csvio import write_measurement
from suspid.models import get_model

FIX = ["--fix", "m1=300", "--fix", "m2=40"]
GAP = (6.0, 6.5)


def _monitor(path: Path) -> list[dict]:
    r = subprocess.run([sys.executable, "-m", "suspid", "monitor", "--model", "quarter2",
                        "--input", str(path), *FIX, "--baseline", "ekf", "--jsonl"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return [json.loads(l) for l in r.stdout.splitlines() if l.strip()]


def _drop_frames(src: Path, dst: Path, t_from: float, t_to: float) -> None:
    """Copy a candump log without the frames stamped in [t_from, t_to) (a dead link)."""
    keep = [line for line in src.read_text().splitlines(keepends=True)
            if not t_from <= float(line[1:line.index(")")]) < t_to]
    dst.write_text("".join(keep))


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, list[dict]]:
    """EKF monitor lines on a 15 s stream (no wear), clean and with a 0.5 s gap."""
    s = damper_wear(get_model("quarter2"), duration=15.0, wear_start=100.0, seed=7)
    d = tmp_path_factory.mktemp("ekfgap")
    clean = d / "clean.log"
    write_log(s, str(clean))
    holed = d / "holed.log"
    _drop_frames(clean, holed, *GAP)
    keep = ~((s.t >= GAP[0]) & (s.t < GAP[1]))
    csv = d / "gap.csv"
    write_measurement(csv, s.t[keep], {k: v[keep] for k, v in s.data.items()})
    return {"clean": _monitor(clean), "log": _monitor(holed), "csv": _monitor(csv)}


def _est(lines: list[dict]) -> list[dict]:
    return [d for d in lines if d["type"] == "estimate"]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["log", "csv"])
def test_the_ekf_stays_consistent_across_a_gap(runs, name: str) -> None:
    """Every window's NIS within its band, no alert, one restart over the 0.5 s gap."""
    out = runs[name]
    summary = out[-1]
    assert summary["type"] == "summary"
    assert summary["nis_windows_inconsistent"] == 0
    assert summary["restarts"] == 1
    assert summary["gap_s"] == pytest.approx(0.5, abs=0.01)
    assert not [d for d in out if d["type"] == "alert"]
    est = _est(out)
    for d in est:
        lo, hi = d["nis_band"]
        assert lo <= d["nis"] <= hi, (d["t"], d["nis"])
        assert not any("inconsistent" in w for w in d["warnings"])
    noted = [d for d in est if d.get("gaps")]
    assert len(noted) == 1 and any("gap in the data" in w for w in noted[0]["warnings"])


@pytest.mark.parametrize("name", ["log", "csv"])
def test_estimates_after_a_gap_are_as_without_it(runs, name: str) -> None:
    """After the gap every free damper and spring is within 1 % (and 1 stderr) of the clean
    run's estimate at the end of the stream; the log's windows (the same ends) agree from
    the first window after the gap on."""
    clean = {round(d["t"], 3): d for d in _est(runs["clean"])}
    got = _est(runs[name])
    last_c, last_g = _est(runs["clean"])[-1], got[-1]
    for k, se in last_g["stderr"].items():
        a, b = last_g["params"][k], last_c["params"][k]
        assert abs(a - b) < 0.01 * b and abs(a - b) < se, (k, a, b, se)
    if name == "log":
        after = [d for d in got if d["t"] > GAP[1]]
        assert after
        for d in after:
            ref = clean[round(d["t"], 3)]
            for k in ("c1", "k1"):
                assert d["params"][k] == pytest.approx(ref["params"][k], rel=0.01)


def test_short_road_holes_are_bridged_long_ones_restart(quarter2) -> None:
    """A hole of ``BRIDGE_SAMPLES`` road samples is stepped through on the interpolated road;
    one sample more is a gap: the filter restarts after it (and only then)."""
    s = damper_wear(quarter2, duration=6.0, wear_start=100.0, seed=2)
    n = s.t.size

    def restarts(hole: int) -> int:
        data = {k: v.copy() for k, v in s.data.items()}
        i0 = n // 2
        data["r"][i0:i0 + hole] = np.nan
        ekf = EKFWindowEstimator(quarter2, quarter2.defaults(), ["c1", "k1"], ["x1", "x2"],
                                 decimate=2)
        ekf.process(s.t[: n // 4], {k: v[: n // 4] for k, v in data.items()})
        ekf.process(s.t, data)
        return ekf.restarts

    assert restarts(BRIDGE_SAMPLES) == 0
    assert restarts(BRIDGE_SAMPLES + 1) == 1
