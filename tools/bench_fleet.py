"""Benchmark of ``suspid fleet``: drives per second on 1 and 2 Dask workers, the history
database's size and the report's time, on a synthetic fleet.

The fleet: ``--drives`` drive logs (default 1000) of ``--duration`` s (default 30) at 200 Hz,
spread over ``--vehicles`` vehicles (default 5) whose dampers wear at 0, 0.25, 0.5, 0.75,
1 %/day ... over 40 days; each drive a ``quarter2`` simulation over its own ISO 8608 road,
encoded by the sensor node's encoder into a candump log (``tools.synthetic_fleet``).
Identification as ``suspid fleet --model quarter2 --fix m1=300 --fix m2=40``.

Usage::

    OPENBLAS_NUM_THREADS=1 python tools/bench_fleet.py               # 1000 drives
    OPENBLAS_NUM_THREADS=1 python tools/bench_fleet.py --drives 100  # a quick run

Prints, per worker count, the wall time of the whole run (cluster start included) and the
steady rate (drives per second between the first and the last finished drive), and the
ratio 2 workers / 1 worker of both.
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository: tools.*

from tools.synthetic_fleet import FleetSpec, VehicleWear, make_fleet  # noqa: E402
from estimator.fleet.runner import AlertConfig, FleetConfig, IdentifySettings, run_fleet


class Clock:
    """Progress callback that records when each drive finished."""

    def __init__(self) -> None:
        self.times: list[float] = []

    def __call__(self, done: int, total: int, failed: int) -> None:
        self.times.append(time.perf_counter())

    def steady_rate(self) -> float:
        if len(self.times) < 2:
            return float("nan")
        return (len(self.times) - 1) / (self.times[-1] - self.times[0])


def run(root: Path, workers: int, db: Path | None) -> tuple[float, float, int]:
    """One fleet run; ``(wall s, steady drives/s, failed)``."""
    settings = IdentifySettings(model="quarter2", fix={"m1": 300.0, "m2": 40.0})
    clock = Clock()
    t0 = time.perf_counter()
    res = run_fleet(FleetConfig(inputs=[str(root)], settings=settings, rule=AlertConfig.per_drive(),
                                workers=workers, db=str(db) if db else None, progress=clock))
    wall = time.perf_counter() - t0
    return wall, clock.steady_rate(), sum(r["status"] != "ok" for r in res.drives)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--drives", type=int, default=1000)
    ap.add_argument("--vehicles", type=int, default=5)
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--workdir", default=None, help="where to write the fleet (default: a temp dir)")
    ap.add_argument("--keep", action="store_true", help="keep the fleet and database")
    args = ap.parse_args()
    work = Path(args.workdir or tempfile.mkdtemp(prefix="bench-fleet-"))
    root = work / "logs"
    try:
        vehicles = [VehicleWear(f"VAN-{i + 1:02d}", c1_rate=0.0025 * i)
                    for i in range(args.vehicles)]
        spec = FleetSpec(vehicles, drives=args.drives, days=40.0, duration=args.duration)
        t0 = time.perf_counter()
        make_fleet(root, spec)
        gen = time.perf_counter() - t0
        size = sum(p.stat().st_size for p in root.rglob("*.log"))
        print(f"fleet: {args.drives} drives of {args.duration:g} s, {args.vehicles} vehicles, "
              f"{size / 1e6:.0f} MB of candump logs, generated in {gen:.1f} s "
              f"({args.drives / gen:.1f} drives/s); cores {os.cpu_count()}, load "
              f"{os.getloadavg()[0]:.1f}")
        results = {}
        db = work / "fleet.sqlite"
        for n in (1, 2):
            wall, rate, failed = run(root, n, db if n == 2 else None)
            results[n] = (wall, rate)
            print(f"workers {n}: {args.drives / wall:6.2f} drives/s end to end ({wall:.1f} s, "
                  f"cluster start included), {rate:6.2f} drives/s steady, {failed} failed; "
                  f"load {os.getloadavg()[0]:.1f}")
        print(f"ratio 2/1 workers: end to end {results[1][0] / results[2][0]:.2f}x, "
              f"steady {results[2][1] / results[1][1]:.2f}x")
        print(f"database: {db.stat().st_size / 1e6:.2f} MB for {args.drives} drives "
              f"({db.stat().st_size / args.drives / 1e3:.1f} kB per drive)")
        t0 = time.perf_counter()
        res = run_fleet(FleetConfig(db=str(db), report=str(work / "report")))
        rep = time.perf_counter() - t0
        page = Path(res.report or "")
        print(f"report from the history: {rep:.2f} s (database read, trends, forecasts, HTML "
              f"with {sum(len(v.monitored) for v in res.vehicles)} plots), "
              f"{page.stat().st_size / 1e3:.0f} kB")
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
        else:
            print(f"kept: {work}")


if __name__ == "__main__":
    main()
