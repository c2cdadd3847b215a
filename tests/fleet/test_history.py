"""``--db``: the SQLite history appended across runs, one drive per log content, and a
report from the history alone."""
from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path
from typing import Any

from tests.fleet.conftest import FIX, Fleet, fleet_json


def _strip(out: dict[str, Any]) -> list[dict[str, Any]]:
    return [{k: v for k, v in d.items()} for d in out["vehicles"]]


def test_history_dedup_and_history_only_report(fleet: Fleet, inprocess: dict[str, Any],
                                               tmp_path: Path) -> None:
    db = tmp_path / "hist" / "fleet.sqlite"
    wear = fleet.root / "VAN-WEAR"
    first = fleet_json("--model", "quarter2", "--input", str(wear), *FIX, "--workers", "0",
                       "--db", str(db))
    assert first["new"] == 6 and first["reused"] == 0
    # the whole fleet now: VAN-WEAR's drives come from the history, not identified again
    second = fleet_json("--model", "quarter2", "--input", str(fleet.root), *FIX, "--workers", "0",
                        "--db", str(db))
    assert second["reused"] == 6 and second["new"] == len(inprocess["drives"]) - 6
    assert second["vehicles"] == inprocess["vehicles"]
    assert second["failed"] == inprocess["failed"] == 2
    key = lambda d: d["path"]  # noqa: E731
    assert sorted(second["drives"], key=key) == sorted(inprocess["drives"], key=key)
    # the same bytes under another name (a re-upload) stay one drive
    copy = fleet.root.parent / "again" / "VAN-WEAR"
    copy.mkdir(parents=True)
    src = Path(fleet.truth[1]["path"])
    shutil.copy(src, copy / "same-drive-renamed.log")
    third = fleet_json("--model", "quarter2", "--input", str(copy), *FIX, "--workers", "0",
                       "--db", str(db))
    assert third["new"] == 0 and third["reused"] == 1
    con = sqlite3.connect(db)
    n_drives = con.execute("SELECT COUNT(*) FROM drives").fetchone()[0]
    n_ok = con.execute("SELECT COUNT(*) FROM drives WHERE status = 'ok'").fetchone()[0]
    n_est = con.execute("SELECT COUNT(*) FROM estimates").fetchone()[0]
    runs = con.execute("SELECT new, reused FROM runs ORDER BY id").fetchall()
    c1 = con.execute("SELECT d.t, e.value FROM drives d JOIN estimates e ON e.drive_id = d.id "
                     "WHERE d.vehicle = 'VAN-WEAR' AND e.parameter = 'c1' ORDER BY d.t").fetchall()
    con.close()
    assert n_drives == len(inprocess["drives"]) and n_ok == n_drives - 2
    assert n_est == 6 * n_ok
    assert runs == [(6, 0), (len(inprocess["drives"]) - 6, 6), (0, 1)]
    assert len(c1) == 6 and c1[0][1] > c1[-1][1]
    # history only: no --input, no --model
    hist = fleet_json("--db", str(db))
    assert hist["new"] == 0 and hist["reused"] == 0
    assert len(hist["drives"]) == len(inprocess["drives"])
    assert hist["failed"] == 2
    assert hist["vehicles"] == third["vehicles"]
    wear_v = {v["vehicle"]: v for v in hist["vehicles"]}["VAN-WEAR"]
    assert wear_v["forecast"] == {v["vehicle"]: v for v in inprocess["vehicles"]}["VAN-WEAR"]["forecast"]
