"""Per-vehicle summaries: drive times unfit for a trend are said, not silently ignored."""
from __future__ import annotations

from typing import Any

from estimator.alerts.engine import AlertConfig
from estimator.fleet.analysis import EPOCH_FLOOR, summarize_fleet, time_warnings

DAY = 86400.0


def _record(vehicle: str, t: float, c1: float, path: str) -> dict[str, Any]:
    params = {"m1": 300.0, "m2": 40.0, "c1": c1, "k1": 20000.0, "c2": 10.0, "k2": 200000.0}
    return {"vehicle": vehicle, "path": path, "t": t, "status": "ok",
            "result": {"model": "quarter2", "params": params, "fixed": ["m1", "m2"], "success": True,
                       "stderr": {k: 0.01 * v for k, v in params.items()}}}


def test_epoch_dated_drives_at_distinct_times_have_no_warning() -> None:
    t0 = 1.7e9
    recs = [_record("VAN", t0 + i * DAY, 1500.0 - 5.0 * i, f"VAN/{i}.log") for i in range(6)]
    (s,) = summarize_fleet(recs, AlertConfig.per_drive())
    assert s.warnings == [] and s.to_json()["warnings"] == []
    assert s.trends["c1"] is not None


def test_relative_time_drives_are_warned_with_the_vehicle_and_count() -> None:
    # CSVs whose t starts at 0: every drive at "1970", all at the same time
    recs = [_record("VAN-CSV", 0.0, 1500.0 - 5.0 * i, f"VAN-CSV/{i}.csv") for i in range(4)]
    (s,) = summarize_fleet(recs, AlertConfig.per_drive())
    text = " | ".join(s.warnings)
    assert "vehicle VAN-CSV: 4 of 4 drives start before 2000-01-01" in text
    assert "4 of 4 drives share their drive time" in text
    assert s.to_json()["warnings"] == s.warnings
    assert s.trends["c1"] is None   # what the warning explains


def test_one_drive_without_a_clock_among_dated_ones_is_named() -> None:
    recs = [_record("TRUCK", 1.7e9 + i * DAY, 1500.0, f"TRUCK/{i}.log") for i in range(3)]
    recs.append(_record("TRUCK", 12.5, 1500.0, "TRUCK/bench.csv"))
    (s,) = summarize_fleet(recs, AlertConfig.per_drive())
    assert len(s.warnings) == 1
    assert "1 of 4 drives start before 2000-01-01 (first sample t = 12.5 s)" in s.warnings[0]


def test_time_warnings_edges() -> None:
    assert time_warnings("V", []) == []
    assert time_warnings("V", [EPOCH_FLOOR, EPOCH_FLOOR + 1]) == []
    (w,) = time_warnings("V", [2e9, 2e9, 2e9 + 1])
    assert w.startswith("vehicle V: 2 of 3 drives share their drive time")
