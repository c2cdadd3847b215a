"""The fleet's decisions on drive records: one confident drive alerts, no forecast in the past,
drives whose fit failed never enter a trend, an old history is read with today's statuses."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from estimator.alerts.engine import AlertConfig
from estimator.fleet.analysis import summarize_fleet
from estimator.fleet.drive import classify
from estimator.fleet.history import History

DAY = 86400.0
T0 = 1.79e9


def _record(vehicle: str, day: float, c1: float, se: float = 5.0, success: bool = True,
            status: str = "ok", **extra: Any) -> dict[str, Any]:
    params = {"m1": 300.0, "m2": 40.0, "c1": c1, "k1": 20000.0, "c2": 300.0, "k2": 200000.0}
    stderr = {k: 0.002 * v for k, v in params.items() if k not in ("m1", "m2")}
    stderr["c1"] = se
    return {"vehicle": vehicle, "path": f"{vehicle}/{day:g}.log", "t": T0 + day * DAY,
            "status": status, "sha256": f"{vehicle}-{day}",
            "result": {"model": "quarter2", "params": params, "fixed": ["m1", "m2"],
                       "stderr": stderr, "success": success, "identifiable": success,
                       "warnings": [] if success else ["not identifiable: c1, k1"], **extra}}


def test_one_drive_confidently_below_the_limit_alerts() -> None:
    """c1 = 741 against a limit of 784 (nominal 1120): the latest drive alone alerts."""
    recs = [_record("VAN", d, 1120.0 - 2.0 * d) for d in (0, 10, 20)]
    recs.append(_record("VAN", 30, 741.0, se=5.0))
    (s,) = summarize_fleet(recs, AlertConfig.per_drive(nominal={"c1": 1120.0}))
    j = s.to_json()
    assert j["alerts"] == ["c1"] and j["risk"] == "alert" and j["limits"]["c1"] == 784.0
    assert "c1" not in j["forecast"]
    # a persistence of two drives stays available on request, not as the default
    (s2,) = summarize_fleet(recs, AlertConfig.per_drive(nominal={"c1": 1120.0}, min_count=2))
    assert s2.to_json()["alerts"] == []
    # an uncertain estimate below the limit is not confident: no alert
    recs[-1] = _record("VAN", 30, 741.0, se=40.0)
    (s3,) = summarize_fleet(recs, AlertConfig.per_drive(nominal={"c1": 1120.0}))
    assert s3.to_json()["alerts"] == []


def test_a_parameter_already_below_is_an_alert_not_a_forecast() -> None:
    """900 +/- 1 against a 1050 limit: an alert, never a forecast dated in the past."""
    recs = [_record("VAN", d, v, se=1.0) for d, v in ((0, 1400), (10, 1300), (20, 1150),
                                                    (30, 900))]
    (s,) = summarize_fleet(recs, AlertConfig.per_drive())
    j = s.to_json()
    assert j["alerts"] == ["c1"] and j["forecast"] == {} and j["risk"] == "alert"


def test_no_forecast_crossing_before_the_latest_drive() -> None:
    """A trend line already at the limit but no confident estimate below it (or persistence
    asked for): the crossing is at the latest drive at the earliest, never before."""
    recs = [_record("VAN", d, v, se=se) for d, v, se in ((0, 1400, 5), (10, 1250, 5),
                                                         (20, 1100, 5), (30, 1040, 60))]
    for rule in (AlertConfig.per_drive(), AlertConfig.per_drive(min_count=2)):
        (s,) = summarize_fleet(recs, rule)
        j = s.to_json()
        assert j["alerts"] == []
        fc = j["forecast"]["c1"]
        assert s.trends["c1"] is not None and s.trends["c1"].value < 1050.0   # line below
        assert fc["crossing_t_low"] >= j["latest_t"] and fc["crossing_t"] >= j["latest_t"]
        assert fc["days_low"] >= 0.0 and fc["days"] >= 0.0
    # a regular forecast counts its days from the latest drive
    recs = [_record("VAN", d, 1500.0 - 5.0 * d, se=3.0) for d in (0, 9, 20, 26, 40)]
    (s,) = summarize_fleet(recs, AlertConfig.per_drive())
    fc = s.to_json()["forecast"]["c1"]
    assert abs(fc["days"] - 50.0) < 3.0
    assert abs(fc["crossing_t"] - (T0 + 40 * DAY) - fc["days"] * DAY) < 1e-3 * DAY


def test_failed_fits_never_enter_a_trend() -> None:
    """Drives with ``success: false`` (an accelerometer-only logger) are unidentified: no
    trend, alert or forecast from them, even with absurd values."""
    assert classify({"success": False, "params": {"c": 1.0}, "fixed": [], "stderr": {},
                     "warnings": ["not identifiable: c, k"]})[0] == "unidentified"
    bad = [_record("VAN", d, 1.9e6 * d, success=False, status="unidentified") for d in range(5)]
    (s,) = summarize_fleet(bad, AlertConfig.per_drive())
    j = s.to_json()
    assert j["drives"] == 0 and j["trend"] == {} and j["forecast"] == {} and j["alerts"] == []
    assert j["risk"] == "no data" and len(j["unidentified"]) == 5
    good = [_record("VAN", d, 1500.0) for d in range(0, 50, 10)]
    (s,) = summarize_fleet(good + bad, AlertConfig.per_drive())
    tr = s.to_json()["trend"]["c1"]
    assert tr["drives"] == 5 and abs(tr["rate_per_day"]) < 1e-6


def test_a_parameter_left_undetermined_never_enters_a_trend() -> None:
    recs = [_record("VAN", d, 1500.0, undetermined=["c2", "k2"]) for d in (0, 10, 20)]
    for r in recs:
        del r["result"]["stderr"]["c2"], r["result"]["stderr"]["k2"]
    (s,) = summarize_fleet(recs, AlertConfig.per_drive())
    j = s.to_json()
    assert set(j["trend"]) == {"c1", "k1"} and set(j["latest_undetermined"]) == {"c2", "k2"}
    assert "c2" not in j["latest"] and j["latest"]["c1"] == 1500.0


def test_an_old_history_lists_failed_fits_as_unidentified(tmp_path: Path) -> None:
    ok = _record("VAN", 0, 1500.0)
    bad = _record("VAN", 1, 3.0e6, success=False)      # stored as 'ok' by an older suspid
    with History(tmp_path / "h.sqlite") as h:
        h.add([ok, bad], "quarter2", "{}")
        drives = {d["path"]: d for d in h.drives()}
    assert drives[ok["path"]]["status"] == "ok"
    assert drives[bad["path"]]["status"] == "unidentified"
    assert drives[bad["path"]]["error"].startswith(f"{bad['path']}: not identified")
