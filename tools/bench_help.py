"""Wall time of ``suspid X --help`` for every subcommand (each in a fresh process).

Usage: ``python tools/bench_help.py [--repeat N] [--modules]``. Prints one line per
subcommand: the best and the median of N runs (s); with ``--modules`` also the heavy
libraries the help loaded (each help should load none of scipy.optimize, matplotlib,
python-can, cantools, asammdf, dask).
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from suspid.cli import SUBCOMMANDS  # noqa: E402  (the worktree's package, above)

HEAVY = ("scipy", "scipy.optimize", "scipy.signal", "matplotlib", "can", "cantools", "asammdf",
         "dask", "distributed", "filterpy", "estimator.identify")

PROBE = ("import sys, runpy; sys.argv = ['suspid', {cmd!r}, '--help']\n"
         "try:\n    runpy.run_module('suspid', run_name='__main__')\n"
         "except SystemExit:\n    pass\n"
         "print('LOADED', ','.join(m for m in {heavy!r} if m in sys.modules), file=sys.stderr)\n")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="runs per subcommand (default 3)")
    ap.add_argument("--modules", action="store_true", help="name the heavy modules each help loads")
    args = ap.parse_args()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    worst = 0.0
    for cmd in SUBCOMMANDS:
        times = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            out = subprocess.run([sys.executable, "-m", "suspid", cmd, "--help"], cwd=ROOT, env=env,
                                 stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            times.append(time.perf_counter() - t0)
            if out.returncode != 0:
                print(f"{cmd}: exit {out.returncode}: {out.stderr.strip()[-300:]}")
                return 1
        line = f"suspid {cmd:9s} --help  best {min(times):.3f} s  median {statistics.median(times):.3f} s"
        if args.modules:
            probe = subprocess.run([sys.executable, "-c", PROBE.format(cmd=cmd, heavy=HEAVY)],
                                   cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.PIPE, text=True)
            loaded = [ln for ln in probe.stderr.splitlines() if ln.startswith("LOADED")]
            line += "  loads: " + (loaded[-1][7:] or "-" if loaded else "?")
        print(line, flush=True)
        worst = max(worst, statistics.median(times))
    print(f"slowest median {worst:.3f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
