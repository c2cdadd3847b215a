"""A fleet like a real one: the road never measured, the payload changing every drive.

Four ``quarter2`` vans log what production cars carry (body acceleration ``x1_ddot`` and
ride height ``d``, CSV with epoch ``t``, no road); each drive has its own body mass (300 to
480 kg) and the spring is held (``--fix k1=20000``), so each drive identifies its body mass
(the payload) and its damper. ``VAN-CROSS`` loses damping and crosses 70 % of nominal
12 days after its last drive; ``VAN-LOW`` is below the limit at its last drive;
``VAN-OK`` (nominal) and ``VAN-89`` (89 % of nominal) are stable.
"""
from __future__ import annotations

import json
import sqlite3
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tools.synthetic_fleet import DAY_S, EPOCH0, write_production_drive
from tests.conftest import write_config
from tests.fleet.conftest import fleet_json, run_fleet_cli

NOMINAL = 1500.0
LIMIT = 0.7 * NOMINAL
DAYS = (0.0, 8.0, 17.0, 23.0, 34.0, 40.0)      # uneven drive spacing
CROSS_DAY = 52.0                                # VAN-CROSS reaches the limit (12 d after its last drive)
ARGS = ["--model", "quarter2", "--fix", "k1=20000", "--nominal", "c1=1500", "--workers", "0"]


def _c1(van: str, day: float) -> float:
    if van == "VAN-CROSS":
        return NOMINAL * (1.0 - 0.3 * day / CROSS_DAY)
    if van == "VAN-LOW":
        return 1300.0 - 350.0 * day / DAYS[-1]    # 950 at the last drive
    return NOMINAL * (0.89 if van == "VAN-89" else 1.0)


@dataclass
class RoadFleet:
    root: Path
    truth: dict[str, dict[str, Any]]    # path -> t, m1, c1


@pytest.fixture(scope="module")
def road_fleet(tmp_path_factory: pytest.TempPathFactory) -> RoadFleet:
    root = tmp_path_factory.mktemp("road-unknown") / "fleet"
    rng = np.random.default_rng(11)
    truth: dict[str, dict[str, Any]] = {}
    for v, van in enumerate(("VAN-CROSS", "VAN-LOW", "VAN-OK", "VAN-89")):
        (root / van).mkdir(parents=True)
        for i, day in enumerate(DAYS):
            t0 = EPOCH0 + day * DAY_S + 3600.0 * v
            m1 = float(rng.uniform(300.0, 480.0))     # payload changes every drive
            path = root / van / f"drive-{i}.csv"
            p = write_production_drive(path, {"m1": m1, "c1": _c1(van, day)}, t0,
                                       duration=16.0, seed=100 * v + i)
            truth[str(path)] = {"t": t0, "m1": m1, "c1": p["c1"]}
    return RoadFleet(root, truth)


@pytest.fixture(scope="module")
def result(road_fleet: RoadFleet, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    report = tmp_path_factory.mktemp("road-report")
    out = fleet_json(*ARGS, "--input", str(road_fleet.root), "--report", str(report))
    out["_html"] = (report / "index.html").read_text(encoding="utf-8")
    return out


@pytest.mark.slow
def test_every_drive_gives_its_body_mass_and_damper(road_fleet: RoadFleet,
                                                    result: dict[str, Any]) -> None:
    assert len(result["drives"]) == 24 and result["failed"] == 0
    for d in result["drives"]:
        true = road_fleet.truth[d["path"]]
        assert d["status"] == "ok" and d["road"] == "unknown", d
        assert abs(d["params"]["m1"] / true["m1"] - 1) < 0.03, (d["path"], d["params"]["m1"])
        assert abs(d["params"]["c1"] / true["c1"] - 1) < 0.03, (d["path"], d["params"]["c1"])
        # the tyres are not determined with the road unknown, and say so
        assert set(d["undetermined"]) == {"m2", "c2", "k2"}
        assert not {"m2", "c2", "k2"} & set(d["stderr"])
    # the road mode was chosen per drive from its record and named
    assert any("road under the tyres is unknown" in w for w in result["drives"][0]["warnings"])


def test_alerts_and_forecasts_follow_the_damper_not_the_load(result: dict[str, Any]) -> None:
    v = {x["vehicle"]: x for x in result["vehicles"]}
    # the damper is monitored; the body mass is the load, the tyres undetermined
    for x in v.values():
        assert set(x["trend"]) == {"c1"}, x["trend"]
        assert set(x["loads"]) == {"m1"} and len(x["loads"]["m1"]) == 6
        assert x["roads"] == {"unknown": 6}
        assert set(x["latest_undetermined"]) == {"m2", "c2", "k2"}
    cross, low = v["VAN-CROSS"], v["VAN-LOW"]
    assert cross["alerts"] == [] and set(cross["forecast"]) == {"c1"}
    fc = cross["forecast"]["c1"]
    true_t = EPOCH0 + CROSS_DAY * DAY_S
    assert fc["crossing_t_low"] <= true_t <= fc["crossing_t_high"], fc
    assert fc["crossing_t_low"] >= cross["latest_t"]
    assert fc["days_low"] <= (true_t - cross["latest_t"]) / DAY_S <= fc["days_high"]
    assert abs(cross["trend"]["c1"]["rate_per_day"] + 0.3 * NOMINAL / CROSS_DAY) \
        < 3 * cross["trend"]["c1"]["stderr"]
    # below the limit at its last drive: one drive is enough; an alert, not a forecast
    assert low["alerts"] == ["c1"] and low["forecast"] == {} and low["risk"] == "alert"
    for name in ("VAN-OK", "VAN-89"):
        assert v[name]["alerts"] == [] and v[name]["forecast"] == {}, v[name]
        assert v[name]["risk"] == "ok"
    assert [x["vehicle"] for x in result["vehicles"]][:2] == ["VAN-LOW", "VAN-CROSS"]


def test_report_shows_road_and_payload_per_drive(result: dict[str, Any]) -> None:
    page = result["_html"]
    table = page.split('id="drives-VAN-CROSS"')[1].split("</table>")[0]
    assert "<th>m1 (load)</th><th>c1</th><th>Undetermined</th>" in table
    assert table.count('<tr class="ok">') == 6 and "not determined" not in table
    assert table.count("<td>unknown</td>") == 6 and table.count("<td>m2, c2, k2</td>") == 6
    assert "road unknown: 6" in page and 'id="unidentified"' in page


@pytest.mark.slow
def test_the_road_mode_is_part_of_the_history_key(road_fleet: RoadFleet, tmp_path: Path) -> None:
    db = tmp_path / "h.sqlite"
    van = str(road_fleet.root / "VAN-OK")
    first = fleet_json(*ARGS, "--input", van, "--db", str(db))
    again = fleet_json(*ARGS, "--input", van, "--db", str(db), "--road", "unknown")
    zero = fleet_json(*ARGS, "--input", van, "--db", str(db), "--road", "zero",
                      "--config", write_config(tmp_path, "[fit]\nrestarts = 1\nmultistart = 0\n"))
    assert first["new"] == 6 and first["reused"] == 0
    assert again["new"] == 6 and again["reused"] == 0       # "auto" and "unknown" differ as keys
    assert zero["new"] == 6 and zero["reused"] == 0          # another road mode: identified again
    assert {d["road"] for d in zero["drives"]} == {"zero"} and len(zero["drives"]) == 6
    con = sqlite3.connect(db)
    roads = [json.loads(r[0])["road"] for r in con.execute("SELECT result FROM drives")]
    con.close()
    assert roads == ["zero"] * 6
    hist = fleet_json("--db", str(db))
    assert hist["reused"] == 6 and {d["road"] for d in hist["drives"]} == {"zero"}


@pytest.mark.slow
def test_accelerometer_only_drives_are_unidentified(tmp_path: Path) -> None:
    """A logger with a body accelerometer alone, fitted as quarter1: no drive is ``ok``, none
    enters a trend; each is listed with its reason, in the JSON, the table and the report."""
    van = tmp_path / "fleet" / "VAN-ACC"
    van.mkdir(parents=True)
    for i in range(3):
        path = van / f"d{i}.csv"
        write_production_drive(path, {}, EPOCH0 + i * DAY_S, duration=8.0, seed=i)
        rows = np.loadtxt(path, delimiter=",", skiprows=1)
        np.savetxt(path, rows[:, :2], fmt=["%.6f", "%.10g"], delimiter=",", header="t,x_ddot",
                   comments="")
    report = tmp_path / "report"
    out = fleet_json("--model", "quarter1", "--input", str(van.parent), "--workers", "0",
                     "--report", str(report))
    assert out["failed"] == 0 and out["unidentified"] == 3
    for d in out["drives"]:
        assert d["status"] == "unidentified" and d["success"] is False
        assert d["error"].startswith(d["path"] + ": not identified")
    (v,) = out["vehicles"]
    assert v["drives"] == 0 and v["trend"] == {} and v["alerts"] == [] and v["forecast"] == {}
    assert v["risk"] == "no data" and len(v["unidentified"]) == 3
    page = (report / "index.html").read_text(encoding="utf-8")
    table = page.split('id="unidentified"')[1].split("</table>")[0]
    assert table.count("<tr>") == 4 and "not identified" in table
    text = run_fleet_cli("--model", "quarter1", "--input", str(van.parent), "--workers", "0"
                         ).stdout
    assert "0 drives identified, 3 not identified, 0 failed" in text
    assert text.count("unidentified: ") == 3
