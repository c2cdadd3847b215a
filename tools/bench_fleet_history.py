"""How a report from the fleet's history grows with the fleet: time and memory of reading
the SQLite history, the trends, alerts and forecasts, and the HTML report, at 100, 300 and
1,000 vans of 10 drives each.

The history is synthetic but shaped like a real one: each drive's stored result is the
``suspid identify --json`` object of a real road-unknown fit (``quarter2``, production
sensors, spring held), its damper and body mass changed per drive (a van's damper wearing
0 to 0.6 %/day with 2.5 % scatter, the payload 300 to 480 kg), written with the fleet's own
:class:`~estimator.fleet.history.History`. Each size runs in a fresh process, so its peak
resident memory is its own.

Phases, each timed:

read_sql
    ``SELECT ... FROM drives`` alone (the rows, the result JSON as text): SQLite's share.
read
    :meth:`History.drives` (the rows and the JSON decoded into records).
analyse
    :func:`estimator.fleet.analysis.summarize_fleet` (per vehicle: the alert engine, the
    robust trend, the forecast).
report
    :func:`estimator.fleet.report.write_report` (the HTML page with its plots).

Usage::

    OPENBLAS_NUM_THREADS=1 python tools/bench_fleet_history.py            # 100, 300, 1000 vans
    OPENBLAS_NUM_THREADS=1 python tools/bench_fleet_history.py --vans 100 300 1000 3000
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from estimator.alerts.engine import AlertConfig
from estimator.fleet.analysis import summarize_fleet
from estimator.fleet.history import History
from estimator.fleet.report import write_report
from estimator.identify import Parameters
from estimator.identify.roadfree import fit_road_unknown
from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement
from suspid.models import get_model
from suspid.simulate import simulate

DAY_S = 86400.0
T0 = 1.79e9
DRIVES = 10


def template() -> dict[str, Any]:
    """A real road-unknown identify result (quarter2, production sensors, k1 held)."""
    model = get_model("quarter2")
    p = model.defaults()
    t, road, x0 = make_scenario(model, "iso8608", duration=12.0, fs=200.0, params=p, seed=3)
    out = simulate(model, p, t, road, x0)
    meas = Measurement(t=t, road={}, measured={c: out[c] for c in model.channel_set("production")})
    res = fit_road_unknown(model, meas, Parameters.for_model(model, fix={"k1": p["k1"]}))
    return res.to_json()


def build(db: Path, vans: int, seed: int = 1) -> None:
    """Write ``vans`` x :data:`DRIVES` drives into a new history at ``db``."""
    base = template()
    rng = np.random.default_rng(seed)
    records = []
    for v in range(vans):
        rate = float(rng.uniform(0.0, 0.006))
        days = np.cumsum(rng.exponential(5.0, DRIVES))
        for k, d in enumerate(days):
            res = json.loads(json.dumps(base))
            c1 = 1500.0 * (1.0 - rate * d) * (1.0 + 0.025 * rng.standard_normal())
            m1 = float(rng.uniform(300.0, 480.0))
            res["params"].update(c1=c1, m1=m1)
            res["stderr"].update(c1=0.003 * c1, m1=0.002 * m1)
            records.append({"path": f"/fleet/VAN-{v:05d}/drive-{k:02d}.csv",
                            "vehicle": f"VAN-{v:05d}", "t": T0 + float(d) * DAY_S,
                            "status": "ok", "error": None, "size": 123_456,
                            "sha256": f"{v:08x}{k:04x}" + "0" * 52, "result": res})
    with History(db) as h:
        h.add(records, "quarter2", json.dumps({"road": "unknown", "fix": {"k1": 20000.0}}))
        h.add_run(time.time(), "quarter2", {"rule": {"nominal": {"c1": 1500.0}}}, len(records),
                  0, 0)


def rss_mb() -> float:
    """Peak resident memory of this process so far (MB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def measure(vans: int, folder: Path) -> dict[str, float]:
    """Time a report from the history of ``vans`` vans (built by ``--build``) in this
    process: each phase's time, the peak resident memory and its growth over the imports."""
    db = folder / f"fleet-{vans}.sqlite"
    out: dict[str, float] = {"vans": vans, "db_mb": db.stat().st_size / 1e6}
    base = rss_mb()
    t = time.perf_counter()
    con = sqlite3.connect(db.resolve().as_uri() + "?mode=ro", uri=True)
    rows = con.execute("SELECT id, path, vehicle, t, status, error, size, result, model "
                       "FROM drives ORDER BY vehicle, t, path").fetchall()
    con.close()
    out["read_sql_s"] = time.perf_counter() - t
    del rows
    t = time.perf_counter()
    with History(db, readonly=True) as h:
        records = h.drives()
    out["read_s"] = time.perf_counter() - t
    rule = AlertConfig.per_drive(nominal={"c1": 1500.0})
    t = time.perf_counter()
    vehicles = summarize_fleet(records, rule)
    out["analyse_s"] = time.perf_counter() - t
    t = time.perf_counter()
    page = write_report(folder / f"report-{vans}", vehicles, records, rule)
    out["report_s"] = time.perf_counter() - t
    out["report_mb"] = page.stat().st_size / 1e6
    out["peak_rss_mb"] = rss_mb()
    out["rss_growth_mb"] = rss_mb() - base
    out["alerts"] = sum(v.risk == "alert" for v in vehicles)
    out["forecasts"] = sum(v.risk == "forecast" for v in vehicles)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vans", type=int, nargs="+", default=[100, 300, 1000])
    ap.add_argument("--one", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--build", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--folder", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.build is not None:
        build(Path(args.folder) / f"fleet-{args.build}.sqlite", args.build)
        return 0
    if args.one is not None:
        print(json.dumps(measure(args.one, Path(args.folder))))
        return 0
    print(f"cores {os.cpu_count()}, load {os.getloadavg()[0]:.1f}; {DRIVES} drives per van")
    print(f"{'vans':>6} {'drives':>7} {'db MB':>6} {'SQL s':>6} {'read s':>7} {'analyse s':>9} "
          f"{'report s':>8} {'total s':>7} {'peak RSS MB':>11} {'growth MB':>9} "
          f"{'report MB':>9}")
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.vans:
            subprocess.run([sys.executable, __file__, "--build", str(n), "--folder", tmp],
                           check=True)
            proc = subprocess.run([sys.executable, __file__, "--one", str(n), "--folder", tmp],
                                  capture_output=True, text=True, check=True)
            r = json.loads(proc.stdout.strip().splitlines()[-1])
            total = r["read_s"] + r["analyse_s"] + r["report_s"]
            print(f"{n:>6} {n * DRIVES:>7} {r['db_mb']:>6.1f} {r['read_sql_s']:>6.2f} "
                  f"{r['read_s']:>7.2f} {r['analyse_s']:>9.2f} {r['report_s']:>8.2f} "
                  f"{total:>7.2f} {r['peak_rss_mb']:>11.0f} {r['rss_growth_mb']:>9.0f} "
                  f"{r['report_mb']:>9.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
