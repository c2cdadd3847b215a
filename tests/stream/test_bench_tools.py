"""The benchmark scripts run and report what docs/monitoring.md quotes (no timing asserted)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_bench_monitor_replay_reports_start_long_and_sustained_rates() -> None:
    r = subprocess.run([sys.executable, str(REPO / "tools" / "bench_monitor.py"), "replay",
                        "--duration", "8", "--long", "16", "--repeat", "1", "--json"],
                       capture_output=True, text=True, timeout=600, cwd=REPO)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)["replay"]
    assert out["data_s"] == 8 and out["long"]["data_s"] == 16
    # 500 Hz x 4 frames per sample plus status frames, every one accepted
    assert 4 * 500 * 8 <= out["frames"] < 4 * 500 * 8 * 1.05
    assert 4 * 500 * 16 <= out["long"]["frames"] < 4 * 500 * 16 * 1.05
    assert out["windows"] >= 3 and out["long"]["windows"] > out["windows"]
    assert out["process_start_s"] > 0 and out["long"]["wall_s"] > 0
    # the rate of the 8 extra seconds; its size depends on the machine's load, not asserted
    assert out["sustained_realtime_factor"] == 8 / (out["long"]["wall_s"] - out["wall_s"])
    assert [a for a, _ in out["long"]["alerts"]] in ([], ["c1"])
    assert out["realtime_factor_end_to_end"] == out["data_s"] / out["wall_s"]


@pytest.mark.slow
def test_bench_monitor_evaluations_times_the_fast_and_general_paths_on_every_model() -> None:
    r = subprocess.run([sys.executable, str(REPO / "tools" / "bench_monitor.py"), "evaluations",
                        "--repeat", "1", "--json"],
                       capture_output=True, text=True, timeout=600, cwd=REPO)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)["evaluations"]
    for name, free in (("quarter2", 4), ("half4", 6), ("full7", 12)):
        row = out[name]
        assert row["free"] == free and row["samples"] == 751
        # every point on the fast path (the timing itself is not asserted)
        assert row["fast_fallbacks"] == 0
        assert row["fast_us"] > 0 and row["general_us"] > 0
        assert row["general_over_fast"] == round(row["general_us"] / row["fast_us"], 2)


@pytest.mark.slow
def test_bench_roadfree_reports_both_roads_side_by_side() -> None:
    r = subprocess.run([sys.executable, str(REPO / "tools" / "bench_roadfree.py"), "--duration",
                        "30", "--record", "8", "--repeat", "1", "--json"],
                       capture_output=True, text=True, timeout=600, cwd=REPO)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    for key in ("nm/measured", "nm/unknown", "ekf/measured", "ekf/unknown"):
        row = out["monitor"][key]
        assert row["estimates"] == 19 and row["cpu_us_per_sample"] > 0
        assert row["c1_rmse_pct"] < 5.0
    idf = out["identify"]
    for road in ("measured", "unknown"):
        assert idf[road]["wall_s_end_to_end"] > 0 and abs(idf[road]["c1"] / 1500.0 - 1) < 0.05
    assert idf["fit_measured_over_unknown"] == round(idf["measured"]["fit_s"]
                                                     / idf["unknown"]["fit_s"], 1)
