"""The fleet's history: an SQLite database (schema in ``docs/fleet.md``) of every drive.

A drive's key is its content hash: the same bytes replace their row and are not identified
again with the same settings; a failed log is one row per path.
"""
from __future__ import annotations

import json
import sqlite3
import time
from pathlib import Path
from typing import Any, Iterable

from estimator.fleet.drive import classify
from suspid.errors import InputError

SCHEMA_VERSION = 2
DISTANCE_COLUMNS = (("odometer_m", "REAL"), ("distance_m", "REAL"), ("distance_source", "TEXT"))
READ = ("ok", "unidentified")

_SCHEMA = """
CREATE TABLE IF NOT EXISTS drives (
    id TEXT PRIMARY KEY, path TEXT NOT NULL, vehicle TEXT NOT NULL, t REAL,
    model TEXT NOT NULL, status TEXT NOT NULL, error TEXT, size INTEGER,
    settings TEXT NOT NULL, result TEXT, processed REAL NOT NULL, odometer_m REAL,
    distance_m REAL, distance_source TEXT);
CREATE INDEX IF NOT EXISTS drives_vehicle_t ON drives (vehicle, t);
CREATE TABLE IF NOT EXISTS estimates (
    drive_id TEXT NOT NULL REFERENCES drives(id) ON DELETE CASCADE,
    parameter TEXT NOT NULL, value REAL NOT NULL, stderr REAL, fixed INTEGER NOT NULL,
    PRIMARY KEY (drive_id, parameter));
CREATE TABLE IF NOT EXISTS runs (
    id INTEGER PRIMARY KEY AUTOINCREMENT, started REAL, finished REAL, model TEXT,
    options TEXT, new INTEGER, reused INTEGER, failed INTEGER);
"""


def drive_id(record: dict[str, Any]) -> str:
    """A drive's key: its content hash (plus the path for a failed log; the path alone if unread)."""
    sha = record.get("sha256")
    if not sha:
        return f"path:{record['path']}"
    return sha if record.get("status") in READ else f"{sha}:{record['path']}"


class History:
    """An open fleet history database at ``path`` (created unless ``readonly``); InputError when it
    is not a usable fleet history or cannot be written.
    """

    #: seconds to wait for another run's write to end before failing
    BUSY_TIMEOUT_S = 60.0

    def __init__(self, path: str | Path, readonly: bool = False) -> None:
        self.path = Path(path)
        self._columns: set[str] = set()
        if self.path.is_dir():
            raise InputError(f"--db {path}: is a directory, expected a database file")
        if not readonly:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        existed = self.path.exists()
        try:
            if readonly:
                self.conn = sqlite3.connect(self.path.resolve().as_uri() + "?mode=ro", uri=True,
                                            timeout=self.BUSY_TIMEOUT_S)
            else:
                self.conn = sqlite3.connect(str(self.path), timeout=self.BUSY_TIMEOUT_S)
            self.conn.execute("PRAGMA foreign_keys = ON")
            version = self.conn.execute("PRAGMA user_version").fetchone()[0]
            if version > SCHEMA_VERSION:
                raise InputError(f"--db {path}: schema version {version}, this suspid reads "
                                 f"up to {SCHEMA_VERSION}")
            if readonly:
                if self.conn.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND "
                                     "name = 'drives'").fetchone() is None:
                    raise InputError(f"--db {path}: not a fleet history (no table drives)")
                self._columns = self._drive_columns()
                return
        except sqlite3.DatabaseError as exc:
            what = "not a usable SQLite database" if existed else "cannot create the history"
            raise InputError(f"--db {path}: {what} ({exc})") from None
        try:
            self.conn.executescript(_SCHEMA)
            have = self._drive_columns()
            for name, kind in DISTANCE_COLUMNS:     # a version 1 history: NULL for old rows
                if name not in have:
                    self.conn.execute(f"ALTER TABLE drives ADD COLUMN {name} {kind}")
            self.conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
            self.conn.commit()
            self._columns = self._drive_columns()
        except sqlite3.DatabaseError as exc:
            raise InputError(f"--db {path}: cannot write the history ({exc})") from None

    def _drive_columns(self) -> set[str]:
        """The columns of table ``drives``."""
        return {r[1] for r in self.conn.execute("PRAGMA table_info(drives)")}

    def _select(self) -> str:
        """The columns :func:`_record` reads (NULL for distance columns a version 1 history lacks)."""
        dist = ", ".join(name if name in self._columns else "NULL"
                         for name, _ in DISTANCE_COLUMNS)
        return f"SELECT id, path, vehicle, t, status, error, size, result, model, {dist} FROM drives"

    def close(self) -> None:
        self.conn.close()

    def __enter__(self) -> "History":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def known(self, settings_key: str) -> dict[str, dict[str, Any]]:
        """Stored drives made with these settings: ``id -> record``."""
        rows = self.conn.execute(self._select() + " WHERE settings = ?", (settings_key,))
        return {r[0]: _record(r) for r in rows}

    def add(self, records: Iterable[dict[str, Any]], model: str, settings_key: str) -> int:
        """Insert or replace drives (one transaction); returns how many (InputError if not writable)."""
        now = time.time()
        n = 0
        try:
            with self.conn:
                for rec in records:
                    did = drive_id(rec)
                    res = rec.get("result")
                    self.conn.execute("DELETE FROM drives WHERE path = ? AND id != ? AND "
                                      "(status != 'ok' OR t = ?)", (rec["path"], did, rec.get("t")))
                    self.conn.execute("DELETE FROM estimates WHERE drive_id = ?", (did,))
                    self.conn.execute(
                        "INSERT OR REPLACE INTO drives (id, path, vehicle, t, model, status, error, "
                        "size, settings, result, processed, odometer_m, distance_m, distance_source) "
                        "VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
                        (did, rec["path"], rec["vehicle"], rec.get("t"), model, rec["status"],
                         rec.get("error"), rec.get("size"), settings_key,
                         json.dumps(res) if res is not None else None, now,
                         rec.get("odometer_m"), rec.get("distance_m"), rec.get("distance_source")))
                    if res is not None:
                        fixed = set(res.get("fixed", []))
                        self.conn.executemany(
                            "INSERT INTO estimates (drive_id, parameter, value, stderr, fixed) "
                            "VALUES (?,?,?,?,?)",
                            [(did, k, float(v), res.get("stderr", {}).get(k), int(k in fixed))
                             for k, v in res["params"].items()])
                    n += 1
        except sqlite3.DatabaseError as exc:
            raise InputError(f"--db {self.path}: cannot store the drives ({exc})") from None
        return n

    def drives(self) -> list[dict[str, Any]]:
        """Every stored drive as a record (``path``, ``vehicle``, ``t``, ``status``, ...)."""
        rows = self.conn.execute(self._select() + " ORDER BY vehicle, t, path")
        return [{**_record(r), "model": r[8]} for r in rows]

    def last_options(self) -> dict[str, Any] | None:
        """The options of the latest run (nominal values, alert settings), if any."""
        row = self.conn.execute("SELECT options FROM runs ORDER BY id DESC LIMIT 1").fetchone()
        return json.loads(row[0]) if row and row[0] else None

    def add_run(self, started: float, model: str, options: dict[str, Any], new: int,
                reused: int, failed: int) -> None:
        """Record a run (its options, counts); InputError if the database cannot be written."""
        try:
            with self.conn:
                self.conn.execute("INSERT INTO runs (started, finished, model, options, new, reused, "
                                  "failed) VALUES (?,?,?,?,?,?,?)",
                                  (started, time.time(), model, json.dumps(options), new, reused,
                                   failed))
        except sqlite3.DatabaseError as exc:
            raise InputError(f"--db {self.path}: cannot store the run ({exc})") from None


def _record(r: tuple[Any, ...]) -> dict[str, Any]:
    """A stored row as a drive record, a read drive's status decided again from its result."""
    did = r[0]
    result = json.loads(r[7]) if r[7] else None
    status, error = r[4], r[5]
    if status in READ:
        status, why = classify(result)
        error = None if why is None else f"{r[1]}: {why}"
    return {"path": r[1], "vehicle": r[2], "t": r[3], "status": status, "error": error,
            "size": r[6], "result": result,
            "sha256": None if did.startswith("path:") else did.split(":", 1)[0],
            "odometer_m": r[9], "distance_m": r[10], "distance_source": r[11]}
