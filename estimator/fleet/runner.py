"""Running a fleet: discover the logs, identify each drive on Dask, keep the history, summarise."""
from __future__ import annotations

import logging
import math
import os
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, TextIO

from distributed import Client, LocalCluster, as_completed

from estimator.alerts.engine import AlertConfig
from estimator.decode.listener import DecodeListener
from estimator.fleet.analysis import VehicleSummary, summarize_fleet
from estimator.fleet.discover import DriveFile, find_drives
from estimator.fleet.drive import (CAN_SUFFIXES, IdentifySettings, cached_database, file_digest,
                                   identify_drive, with_declared_channels)
from estimator.fleet.history import READ, History, drive_id
from estimator.fleet.report import prepare_report_folder, write_report
from suspid.errors import InputError, UsageError
from suspid.models import get_model

Progress = Callable[[int, int, int], None]


def available_cpus() -> int:
    """The CPUs this process may run on (its affinity mask where there is one, else the count)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


class ProgressBar:
    """A text progress bar on a stream: one redrawn line on a terminal, else a line per tenth."""

    def __init__(self, stream: TextIO = sys.stderr, width: int = 30) -> None:
        self.stream = stream
        self.width = width
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        self.t0 = time.perf_counter()
        self._last_tenth = -1

    def __call__(self, done: int, total: int, failed: int) -> None:
        frac = done / total if total else 1.0
        tenth = int(frac * 10)
        if not self.tty and tenth == self._last_tenth and done < total:
            return
        self._last_tenth = tenth
        fill = int(round(frac * self.width))
        dt = time.perf_counter() - self.t0
        rate = done / dt if dt > 0 else 0.0
        line = (f"[{'#' * fill}{'.' * (self.width - fill)}] {done}/{total} drives, "
                f"{failed} failed, {rate:.1f} drives/s")
        self.stream.write("\r" + line + ("\n" if done >= total else "") if self.tty else line + "\n")
        self.stream.flush()


@dataclass
class FleetConfig:
    """What ``suspid fleet`` was asked to do (``inputs`` empty: report from ``db`` alone; ``workers``
    0: no cluster; ``progress(done, total, failed)`` after each drive).
    """

    inputs: list[str] = field(default_factory=list)
    settings: IdentifySettings | None = None
    rule: AlertConfig = field(default_factory=AlertConfig.per_drive)
    scheduler: str | None = None
    workers: int | None = None
    db: str | None = None
    report: str | None = None
    progress: Progress | None = None


@dataclass
class FleetResult:
    """Outcome of a fleet run."""

    drives: list[dict[str, Any]]
    vehicles: list[VehicleSummary]
    duplicates: list[dict[str, str]] = field(default_factory=list)
    new: int = 0
    reused: int = 0
    report: str | None = None
    seconds: float = 0.0

    def to_json(self) -> dict[str, Any]:
        """The contract's object: ``drives``, ``vehicles``, ``failed`` (+ run facts)."""
        drives = [drive_json(r) for r in self.drives]
        return {"drives": drives, "vehicles": [v.to_json() for v in self.vehicles],
                "failed": sum(1 for d in drives if d["status"] == "failed"),
                "unidentified": sum(1 for d in drives if d["status"] == "unidentified"),
                "new": self.new, "reused": self.reused, "duplicates": self.duplicates,
                "report": self.report, "seconds": self.seconds}


def drive_json(rec: dict[str, Any]) -> dict[str, Any]:
    """A drive entry: contract fields first, then the rest of identify's result."""
    res = rec.get("result") or {}
    out: dict[str, Any] = {"path": rec["path"], "vehicle": rec["vehicle"], "t": rec.get("t"),
                           "params": res.get("params"), "stderr": res.get("stderr"),
                           "status": rec["status"], "error": rec.get("error"),
                           "sha256": rec.get("sha256")}
    for k in ("model", "road", "fixed", "cost", "nfev", "success", "rms_residual",
              "identifiable", "undetermined", "warnings", "offset", "frames"):
        if k in res:
            out[k] = res[k]
    if rec.get("distance_source") is not None:
        for key, m in (("odometer_km", rec.get("odometer_m")),
                       ("distance_km", rec.get("distance_m"))):
            out[key] = None if m is None else round(float(m) / 1e3, 4)
        out["distance_source"] = rec["distance_source"]
    return out


def execute(jobs: list[tuple[str, str, str | None]], settings: IdentifySettings,
            scheduler: str | None = None, workers: int | None = None,
            progress: Progress | None = None) -> list[dict[str, Any]]:
    """Identify drives ``(path, vehicle, sha256 or None)`` on Dask (local cluster, ``scheduler``, or
    in this process with ``workers=0``); records in job order.
    """
    if not jobs:
        return []
    total = len(jobs)
    failed = 0
    if scheduler is None and workers == 0:
        inline: list[dict[str, Any]] = []
        for i, (p, v, d) in enumerate(jobs, 1):
            inline.append(identify_drive(p, v, settings, d))
            failed += inline[-1]["status"] == "failed"
            if progress:
                progress(i, total, failed)
        return inline
    if workers is not None and workers < 0:
        raise UsageError(f"--workers: expected an integer >= 0, got {workers}")
    cluster = None
    try:
        if scheduler is not None:
            try:
                client = Client(scheduler)   # timeout: distributed.comm.timeouts.connect
            except (OSError, TimeoutError, ValueError) as exc:
                raise UsageError(f"--scheduler {scheduler}: cannot connect to a Dask scheduler "
                                 f"({' '.join(str(exc).split())})") from None
        else:
            cpus = available_cpus()   # local workers: at most the CPUs and the drives
            n = max(1, min(cpus if workers is None else workers, cpus, total))
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=logging.ERROR)
            client = Client(cluster)
        try:
            paths, vehicles, digests = (list(x) for x in zip(*jobs))
            futures = client.map(identify_drive, paths, vehicles, [settings] * total, digests)
            index = {f.key: i for i, f in enumerate(futures)}
            out: list[dict[str, Any] | None] = [None] * total
            done = 0
            for fut in as_completed(futures):
                i = index[fut.key]
                try:
                    rec = fut.result()
                except Exception as exc:  # noqa: BLE001 - a lost worker fails its drive only
                    p, v, d = jobs[i]
                    rec = {"path": p, "vehicle": v, "sha256": d, "size": None, "t": None,
                           "status": "failed", "result": None,
                           "error": " ".join(f"{p}: the Dask task failed: "
                                             f"{type(exc).__name__}: {exc}".split())}
                out[i] = rec
                done += 1
                failed += rec["status"] == "failed"
                if progress:
                    progress(done, total, failed)
            return [r for r in out if r is not None]
        finally:
            client.close()
    finally:
        if cluster is not None:
            cluster.close()


def run_fleet(config: FleetConfig) -> FleetResult:
    """Discover, identify, store and summarise a fleet's drives (``suspid fleet``).

    UsageError for missing or bad options; InputError for a missing input or no drive log found.
    """
    t_start = time.time()
    wall = time.perf_counter()
    if not config.inputs and config.db is None:
        raise UsageError("give --input DIR_OR_GLOB... (and --model), or --db PATH to report "
                         "from the history")
    files: list[DriveFile] = []
    if config.inputs:
        if config.settings is None:
            raise UsageError("--input needs --model")
        files = find_drives(config.inputs)
        if not files:
            raise InputError(f"--input {' '.join(config.inputs)}: no drive log found (expected "
                             f"files ending in {', '.join(CAN_SUFFIXES)} or .csv)")
        # fail early (exit 2) on options that would fail every drive (parameters, DBC, signal map)
        config.settings.parameters()
        if any(Path(f.path).suffix.lower() in CAN_SUFFIXES for f in files):
            db = cached_database(config.settings.dbc)
            DecodeListener(config.settings.model, db, with_declared_channels(
                config.settings.signal_map, db, get_model(config.settings.model)))
    if not config.inputs and config.db is not None and not Path(config.db).is_file():
        raise InputError(f"--db {config.db}: no such history database (a run with --input "
                         "creates it)")
    if config.report is not None:
        prepare_report_folder(config.report)
    history = (History(config.db, readonly=not config.inputs) if config.db is not None
               else None)
    try:
        rule = config.rule
        if history is not None and not config.inputs and not rule.nominal:
            last = history.last_options()
            if last and last.get("rule", {}).get("nominal"):
                rule = replace(rule, nominal=dict(last["rule"]["nominal"]))
        records: list[dict[str, Any]] = []
        new = reused = 0
        settings = config.settings
        if files and settings is not None:
            records, new, reused = _identify(files, settings, history, config)
        records, duplicates = _dedupe(records)
        if history is not None:
            if files and settings is not None:
                history.add(records, settings.model, settings.key())
                history.add_run(t_start, settings.model,
                                {"settings": settings.key(), "rule": rule.to_json(),
                                 "inputs": list(config.inputs)},
                                new, reused, sum(r["status"] == "failed" for r in records))
            records = history.drives()
            if not files:
                # a report from the history alone: every read drive comes from it
                reused = sum(r["status"] in READ for r in records)
        # by vehicle, then time (failed ones without a time last), then path
        records = sorted(records, key=lambda r: (r["vehicle"], r["t"] if r.get("t") is not None
                                                 else math.inf, r["path"]))
        vehicles = summarize_fleet(records, rule)
        result = FleetResult(records, vehicles, duplicates, new, reused)
        if config.report is not None:
            result.report = str(write_report(config.report, result.vehicles, result.drives, rule))
        result.seconds = time.perf_counter() - wall
        return result
    finally:
        if history is not None:
            history.close()


def _identify(files: list[DriveFile], settings: IdentifySettings, history: History | None,
              config: FleetConfig) -> tuple[list[dict[str, Any]], int, int]:
    """Records of ``files`` in order, stored ones reused: ``(records, new, reused)``."""
    known = history.known(settings.key()) if history is not None else {}
    jobs: list[tuple[str, str, str | None]] = []
    reuse: dict[int, dict[str, Any]] = {}
    for i, f in enumerate(files):
        try:
            digest = file_digest(f.path) if history is not None else None
        except OSError:
            digest = None       # the task reports the reason
        if digest is not None and digest in known and known[digest]["status"] in READ:
            reuse[i] = {**known[digest], "path": f.path, "vehicle": f.vehicle}
        else:
            jobs.append((f.path, f.vehicle, digest))
    done = iter(execute(jobs, settings, config.scheduler, config.workers, config.progress))
    records = [reuse[i] if i in reuse else next(done) for i in range(len(files))]
    return records, len(jobs), len(reuse)


def _dedupe(records: list[dict[str, Any]]) -> tuple[list[dict[str, Any]], list[dict[str, str]]]:
    """One record per content (the first path in sorted order); the copies listed."""
    seen: dict[str, str] = {}
    out, dups = [], []
    for r in records:
        key = drive_id(r)
        if key in seen:
            dups.append({"path": r["path"], "same_as": seen[key]})
            continue
        seen[key] = r["path"]
        out.append(r)
    return out, dups

