"""Forecasts in km: a fleet whose logs carry the odometer (J1939 VDHR over CAN, mapped from
the DBC) forecasts the crossing's odometer reading with an interval holding the true one; a
fleet without a distance signal has no km keys and says so; old histories migrate."""
from __future__ import annotations

import json
import sqlite3
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from estimator.fleet.analysis import drive_positions
from estimator.fleet.drive import IdentifySettings, drive_distance, identify_drive
from estimator.fleet.history import History
from tools.synthetic_fleet import (DISTANCE_MAP, EPOCH0, FleetSpec, VehicleWear,
                                       distance_dbc, make_fleet)
from suspid.can.dbc import load_dbc
from suspid.can.signal_map import SignalMap
from suspid.io.csvio import Measurement, read_measurement
from suspid.models import get_model
from tests.fleet.conftest import FIX, Fleet, fleet_json, run_fleet_cli

KM_KEYS = ("crossing_km", "crossing_km_low", "crossing_km_high")


@pytest.fixture(scope="module")
def odometer_fleet(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, FleetSpec, Path]:
    """One wearing van (damper -0.5 %/day: the limit on day 60) driving 180 km a day, its
    six candump logs carrying the odometer as J1939 VDHR from the engine controller."""
    root = tmp_path_factory.mktemp("odo") / "logs"
    spec = FleetSpec([VehicleWear("VAN-ODO", c1_rate=0.005, km_per_day=180.0)], drives=6,
                     days=40.0, duration=8.0, fs=200.0, distance="odometer")
    make_fleet(root, spec)
    return root, spec, root / "distance.dbc"


@pytest.mark.slow
def test_odometer_over_can_gives_the_crossing_in_km(odometer_fleet: tuple[Path, FleetSpec, Path],
                                                    tmp_path: Path) -> None:
    root, spec, dbc = odometer_fleet
    van = spec.vehicles[0]
    db = tmp_path / "h.sqlite"
    args = ["--model", "quarter2", "--input", str(root), "--dbc", str(dbc), "--map",
            DISTANCE_MAP["odometer"], *FIX, "--workers", "0", "--db", str(db)]
    out = fleet_json(*args)
    for d in out["drives"]:
        assert d["status"] == "ok" and d["distance_source"] == "odometer"
        assert d["frames"]["j1939"]["messages"]["VDHR"]["source"] == "0x00"
        # VDHR's resolution is 5 m; the drive covers 8 s at 50 km/h
        assert abs(d["odometer_km"] - van.odometer_m(d["t"]) / 1e3) <= 0.005
        assert abs(d["distance_km"] - 50 / 3.6 * 8.0 / 1e3) <= 0.006
    (v,) = out["vehicles"]
    assert v["distance"]["source"] == "odometer" and v["distance"]["drives"] == 6
    fc = v["forecast"]["c1"]
    true_t = spec.crossing_t(van, "c1", 0.3)
    assert true_t is not None
    true_km = van.odometer_m(true_t) / 1e3
    assert fc["crossing_t_low"] <= true_t <= fc["crossing_t_high"]     # the contract's keys
    assert fc["crossing_km_low"] <= true_km <= fc["crossing_km_high"]
    assert fc["crossing_km_low"] < fc["crossing_km"] < fc["crossing_km_high"]
    assert fc["crossing_km_low"] >= v["distance"]["odometer_km"]
    rate = v["trend_km"]["c1"]["rate_per_km"]
    assert abs(rate - (-1500.0 * 0.005 / 180.0)) < 3 * v["trend_km"]["c1"]["stderr"]
    # the history keeps the distance: a report from it alone has the same km forecast
    again = fleet_json("--db", str(db))
    assert again["vehicles"][0]["forecast"]["c1"]["crossing_km"] == fc["crossing_km"]
    text = run_fleet_cli("--db", str(db), "--report", str(tmp_path / "rep")).stdout
    assert f"at {fc['crossing_km']:,.0f} km" in text
    page = (tmp_path / "rep" / "index.html").read_text(encoding="utf-8")
    assert f"at {fc['crossing_km']:,.0f} km" in page and "no distance signal" not in page


def test_fleet_without_distance_has_no_km_keys(fleet: Fleet, inprocess: dict[str, Any]) -> None:
    v = {x["vehicle"]: x for x in inprocess["vehicles"]}
    wear = v["VAN-WEAR"]
    assert wear["forecast"]["c1"]["crossing_t"] is not None
    assert not set(KM_KEYS) & set(wear["forecast"]["c1"])
    assert wear["distance"] == {"source": None, "odometer_km": None, "drives": 0}
    assert wear["trend_km"] == {}
    assert all("odometer_km" not in d for d in inprocess["drives"])


@pytest.mark.slow
def test_text_and_report_say_no_distance_signal(fleet: Fleet, tmp_path: Path) -> None:
    proc = run_fleet_cli("--model", "quarter2", "--input", str(fleet.root / "VAN-WEAR"), *FIX,
                         "--workers", "0", "--report", str(tmp_path / "rep"))
    assert "no distance signal" in proc.stdout
    page = (tmp_path / "rep" / "index.html").read_text(encoding="utf-8")
    assert "no distance signal" in page


def test_speed_integrates_to_the_distance_and_positions_accumulate(tmp_path: Path) -> None:
    """A CSV drive with a speed column: the distance is the speed's integral; positions are
    the distance logged before each drive (unidentified drives count: they were driven)."""
    spec = FleetSpec([VehicleWear("VAN-S")], drives=1, duration=4.0, fs=100.0, fmt=".csv",
                     distance="speed")
    (truth,) = make_fleet(tmp_path, spec)
    meas = read_measurement(truth["path"], get_model("quarter2"))
    assert not any("speed" in w for w in meas.warnings)          # a known column
    d = drive_distance(meas)
    span = float(meas.t[-1] - meas.t[0])
    assert d["distance_source"] == "speed" and d["odometer_m"] is None
    assert d["distance_m"] == pytest.approx(50 / 3.6 * span, rel=1e-9)
    recs = [{"path": f"{i}.csv", "t": EPOCH0 + i, "distance_m": 100.0 * (i + 1),
             "odometer_m": None, "status": st} for i, st in enumerate(("ok", "unidentified", "ok"))]
    source, pos = drive_positions(recs[::-1])
    assert source == "speed"
    assert [pos[(r["path"], r["t"])] for r in recs] == [0.0, 100.0, 300.0]


def test_odometer_beats_speed_and_a_backwards_odometer_gives_none() -> None:
    t = np.linspace(0.0, 10.0, 11)
    both = Measurement(t=t, aux={"odometer": 5000.0 + 10.0 * t, "speed": np.full(11, 9.0)})
    assert drive_distance(both) == {"odometer_m": 5000.0, "distance_m": 100.0,
                                    "distance_source": "odometer"}
    back = Measurement(t=t, aux={"odometer": 5000.0 - t})
    assert drive_distance(back)["distance_source"] is None
    gaps = Measurement(t=t, aux={"odometer": np.where(t % 2 == 0, 5000.0 + t, np.nan)})
    assert drive_distance(gaps)["distance_m"] == 10.0


def test_speed_in_kmh_without_a_scale_is_named(tmp_path: Path) -> None:
    db = load_dbc(distance_dbc(tmp_path / "d.dbc"))
    smap = SignalMap.from_strings(["speed=CCVS1.WheelBasedVehicleSpeed"])
    (msg,) = smap.unit_warnings(db, get_model("quarter2"))
    assert "'km/h'" in msg and "m/s" in msg and "*0.277778" in msg
    assert SignalMap.from_strings([DISTANCE_MAP["speed"]]).unit_warnings(db, get_model("quarter2")) == []


def test_a_version_1_history_is_migrated_with_null_distances(tmp_path: Path) -> None:
    db = tmp_path / "old.sqlite"
    con = sqlite3.connect(db)
    con.executescript("""
        CREATE TABLE drives (id TEXT PRIMARY KEY, path TEXT NOT NULL, vehicle TEXT NOT NULL,
            t REAL, model TEXT NOT NULL, status TEXT NOT NULL, error TEXT, size INTEGER,
            settings TEXT NOT NULL, result TEXT, processed REAL NOT NULL);
        CREATE TABLE estimates (drive_id TEXT NOT NULL, parameter TEXT NOT NULL,
            value REAL NOT NULL, stderr REAL, fixed INTEGER NOT NULL,
            PRIMARY KEY (drive_id, parameter));
        CREATE TABLE runs (id INTEGER PRIMARY KEY AUTOINCREMENT, started REAL, finished REAL,
            model TEXT, options TEXT, new INTEGER, reused INTEGER, failed INTEGER);
        PRAGMA user_version = 1;""")
    con.execute("INSERT INTO drives VALUES ('a', 'V/1.log', 'V', 1.8e9, 'quarter2', 'failed', "
                "'V/1.log: bad', 10, '{}', NULL, 0)")
    con.commit()
    con.close()
    with History(db, readonly=True) as h:            # read as it is
        (old,) = h.drives()
    assert old["odometer_m"] is None and old["distance_source"] is None
    with History(db) as h:
        h.add([{"path": "V/2.log", "vehicle": "V", "t": 1.9e9, "status": "failed",
                "sha256": "b", "error": "x", "odometer_m": 1234.0, "distance_m": 56.0,
                "distance_source": "odometer"}], "quarter2", "{}")
        rows = {r["path"]: r for r in h.drives()}
    assert rows["V/1.log"]["odometer_m"] is None
    assert (rows["V/2.log"]["odometer_m"], rows["V/2.log"]["distance_m"]) == (1234.0, 56.0)
    con = sqlite3.connect(db)
    assert con.execute("PRAGMA user_version").fetchone()[0] == 2
    con.close()
    json.dumps(rows)   # records stay JSON-ready


def test_speed_over_can_is_integrated_to_the_drive_distance(tmp_path: Path) -> None:
    """A candump drive carrying J1939 CCVS1 (km/h, 10 Hz, from the engine controller) beside
    suspid's sensor messages: the speed, mapped with its factor to m/s, is integrated to
    the distance the drive covered."""
    spec = FleetSpec([VehicleWear("VAN-SPD")], drives=1, duration=6.0, fs=200.0,
                     distance="speed")
    (truth,) = make_fleet(tmp_path, spec)
    settings = IdentifySettings(model="quarter2", fix={"m1": 300.0, "m2": 40.0},
                                dbc=str(tmp_path / "distance.dbc"),
                                signal_map=SignalMap.from_strings([DISTANCE_MAP["speed"]]))
    rec = identify_drive(str(truth["path"]), "VAN-SPD", settings)
    assert rec["status"] == "ok", rec["error"]
    assert rec["distance_source"] == "speed" and rec["odometer_m"] is None
    # frames every 0.1 s from the first sample to the last full period before the end
    span = np.floor((6.0 - 1.0 / 200.0) / 0.1) * 0.1
    assert rec["distance_m"] == pytest.approx(50 / 3.6 * span, abs=0.01)
