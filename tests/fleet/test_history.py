"""``--db``: the SQLite history appended across runs, one drive per log content, and a
report from the history alone."""
from __future__ import annotations

import sqlite3
from typing import Any

import pytest

from tests.fleet.conftest import run_fleet_cli, Fleet, HistoryRuns, fleet_json


@pytest.mark.slow
def test_history_dedup_and_history_only_report(fleet: Fleet, inprocess: dict[str, Any],
                                               history: HistoryRuns) -> None:
    n = len(inprocess["drives"])
    first, second, third = history.first, history.second, history.third
    assert first["new"] == 6 and first["reused"] == 0
    # the whole fleet next: VAN-WEAR's drives come from the history, not identified again
    assert second["reused"] == 6 and second["new"] == n - 6
    assert second["vehicles"] == inprocess["vehicles"]
    assert second["failed"] == inprocess["failed"] == 2
    key = lambda d: d["path"]  # noqa: E731
    assert sorted(second["drives"], key=key) == sorted(inprocess["drives"], key=key)
    # the same bytes under another name (a re-upload) stay one drive
    assert third["new"] == 0 and third["reused"] == 1
    assert len(third["drives"]) == n
    assert str(history.copy) in {d["path"] for d in third["drives"]}
    con = sqlite3.connect(history.db)
    n_drives = con.execute("SELECT COUNT(*) FROM drives").fetchone()[0]
    n_ok = con.execute("SELECT COUNT(*) FROM drives WHERE status = 'ok'").fetchone()[0]
    n_est = con.execute("SELECT COUNT(*) FROM estimates").fetchone()[0]
    runs = con.execute("SELECT new, reused FROM runs ORDER BY id").fetchall()
    c1 = con.execute("SELECT d.t, e.value FROM drives d JOIN estimates e ON e.drive_id = d.id "
                     "WHERE d.vehicle = 'VAN-WEAR' AND e.parameter = 'c1' ORDER BY d.t").fetchall()
    con.close()
    assert n_drives == n and n_ok == n - 2
    assert n_est == 6 * n_ok
    assert runs == [(6, 0), (n - 6, 6), (0, 1)]
    assert len(c1) == 6 and c1[0][1] > c1[-1][1]
    # history only: no --input, no --model
    hist = fleet_json("--db", str(history.db))
    # every identified drive is taken from the history (as a run with --input counts them)
    assert hist["new"] == 0 and hist["reused"] == n_ok
    assert f"0 new, {n_ok} from the history" in run_fleet_cli("--db", str(history.db)).stdout
    assert len(hist["drives"]) == n and hist["failed"] == 2
    assert hist["vehicles"] == third["vehicles"]
    by = {v["vehicle"]: v for v in inprocess["vehicles"]}
    assert [v["forecast"] for v in hist["vehicles"]] == [by[v["vehicle"]]["forecast"]
                                                         for v in hist["vehicles"]]
