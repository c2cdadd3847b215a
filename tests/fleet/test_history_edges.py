"""``--db`` edge cases a fleet meets: logs that grow or get repaired at the same path, many
failed files with the same bytes, a history read while another run writes, and the number
of local workers."""
from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import Any

import pytest

from estimator.fleet import runner
from estimator.fleet.history import History
from estimator.fleet.runner import FleetConfig, execute, run_fleet
from estimator.fleet.drive import IdentifySettings
from tools.synthetic_fleet import EPOCH0, FleetSpec, VehicleWear, write_drive
from suspid.can.dbc import load_dbc
from suspid.errors import InputError
from tests.fleet.conftest import run_fleet_cli

FAST = IdentifySettings(model="quarter2", fix={"m1": 300.0, "m2": 40.0}, restarts=1,
                        multistart=0)


def _run(root: Path, db: Path) -> dict[str, Any]:
    return run_fleet(FleetConfig(inputs=[str(root)], settings=FAST, workers=0,
                                 db=str(db))).to_json()


def test_failed_files_and_a_log_that_grows_at_its_path(tmp_path: Path) -> None:
    root, db = tmp_path / "fleet", tmp_path / "h.sqlite"
    full = tmp_path / "full.log"
    spec = FleetSpec([VehicleWear("VAN-A")], duration=4.0, fs=200.0)
    write_drive(full, spec, spec.vehicles[0], EPOCH0, seed=3, db=load_dbc(None))
    lines = full.read_text().splitlines(keepends=True)
    for rel in ("VAN-A/d.log", "VAN-A/empty.log", "VAN-B/empty.log"):
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text("")                # a logger's empty files: same bytes
    drive = root / "VAN-A" / "d.log"

    first = _run(root, db)                         # three failed files, two vehicles
    assert first["failed"] == 3 and first["duplicates"] == []
    assert {v["vehicle"]: v["failed"] for v in first["vehicles"]} == {"VAN-A": 2, "VAN-B": 1}

    drive.write_text("".join(lines[: len(lines) // 2]))   # upload half done: a drive
    second = _run(root, db)
    assert second["failed"] == 2 and second["new"] == 3
    at = [d for d in second["drives"] if d["path"] == str(drive)]
    assert [d["status"] for d in at] == ["ok"]     # the failed row of the path replaced

    drive.write_text("".join(lines))               # upload complete: the same drive, grown
    third = _run(root, db)
    at = [d for d in third["drives"] if d["path"] == str(drive)]
    assert [d["status"] for d in at] == ["ok"] and third["new"] == 3
    assert abs(at[0]["t"] - EPOCH0) < 1e-6
    assert third["failed"] == 2 and len(third["drives"]) == 3
    con = sqlite3.connect(db)
    rows = con.execute("SELECT path, status FROM drives ORDER BY path").fetchall()
    n_est = con.execute("SELECT COUNT(*) FROM estimates").fetchone()[0]
    con.close()
    assert rows == [(str(root / "VAN-A" / "d.log"), "ok"),
                    (str(root / "VAN-A" / "empty.log"), "failed"),
                    (str(root / "VAN-B" / "empty.log"), "failed")]
    assert n_est == 6                              # one drive's estimates, none orphaned

    # another drive written to the same path later (a new first timestamp) is added
    write_drive(drive, spec, spec.vehicles[0], EPOCH0 + 86400.0, seed=4, db=load_dbc(None))
    fourth = _run(root, db)
    assert sorted(d["t"] for d in fourth["drives"] if d["path"] == str(drive)) == \
        pytest.approx([EPOCH0, EPOCH0 + 86400.0])


def test_history_report_reads_while_another_run_writes(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """A report from the history only reads: it works while another run holds the write
    lock (and on a read-only file or mount) and leaves the file's bytes alone."""
    db = tmp_path / "h.sqlite"
    with History(db) as h:
        h.add([{"path": "V/a.log", "vehicle": "V", "t": 1.8e9, "status": "failed",
                "error": "V/a.log: bad", "sha256": "ab" * 32}], "quarter2", "{}")
    before = db.read_bytes()
    writer = sqlite3.connect(db)
    writer.execute("BEGIN IMMEDIATE")              # another run in its write transaction
    monkeypatch.setattr(History, "BUSY_TIMEOUT_S", 0.5, raising=False)
    try:
        out = run_fleet(FleetConfig(db=str(db))).to_json()
    finally:
        writer.rollback()
        writer.close()
    assert out["failed"] == 1 and out["drives"][0]["sha256"] == "ab" * 32
    assert db.read_bytes() == before
    other = tmp_path / "other.sqlite"
    con = sqlite3.connect(other)
    con.execute("CREATE TABLE notes (x)")
    con.commit()
    con.close()
    with pytest.raises(InputError, match="not a fleet history"):
        run_fleet(FleetConfig(db=str(other)))


def test_no_more_local_workers_than_drives_or_cpus(monkeypatch: pytest.MonkeyPatch) -> None:
    """``--workers 500`` for 2 drives starts 2 worker processes, not 500; for 40 drives on
    3 available CPUs, 3."""
    started: list[int] = []

    class Stop(Exception):
        pass

    def fake_cluster(**kw: Any) -> None:
        started.append(kw["n_workers"])
        raise Stop

    monkeypatch.setattr(runner, "LocalCluster", fake_cluster)
    for workers in (500, None):
        with pytest.raises(Stop):
            execute([("a.log", "V", None), ("b.log", "V", None)], FAST, workers=workers)
    assert started == [2, min(runner.available_cpus(), 2)]
    monkeypatch.setattr(runner, "available_cpus", lambda: 3)
    started.clear()
    for workers in (500, None, 2):
        with pytest.raises(Stop):
            execute([(f"{i}.log", "V", None) for i in range(40)], FAST, workers=workers)
    assert started == [3, 3, 2]


@pytest.mark.slow
def test_more_workers_than_cpus_is_warned_about(tmp_path: Path) -> None:
    """``suspid fleet --workers N`` above the available CPUs says how many it uses."""
    n = runner.available_cpus() + 5
    proc = run_fleet_cli("--model", "quarter2", "--input", str(tmp_path / "none"),
                         "--workers", str(n), check=False)
    assert f"warning: --workers {n}: {runner.available_cpus()} CPU(s) available" in proc.stderr
