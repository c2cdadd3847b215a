#!/usr/bin/env python3
"""Benchmark: the full half4 L27 design with both costs, from 0.5x the truth.

Runs ``suspid doe --model half4 --cost C --json`` for C = sse and frobenius as
subprocesses (process start included), one after the other, and prints successes, wall
time and CPU time of each and in total. Target: under 2 minutes wall on the project
machine (2 cores shared with other work; CPU time shows what the machine load costs).

Usage::

    python tools/bench_doe.py [--model half4] [--init-scale 0.5] [--json]
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path


#: the console script of the running interpreter's environment (as a user runs it), or
#: ``python -m suspid`` when it is not installed as a script
SUSPID = ([str(Path(sys.executable).with_name("suspid"))]
          if Path(sys.executable).with_name("suspid").exists() else [sys.executable, "-m", "suspid"])

def _cpu_children() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default="half4", choices=["quarter1", "quarter2", "half4"])
    ap.add_argument("--init-scale", default="0.5")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args()
    rows = []
    t_all = time.perf_counter()
    cpu_all = _cpu_children()
    for cost in ("sse", "frobenius"):
        cmd = [*SUSPID, "doe", "--model", args.model, "--cost", cost,
               "--init-scale", args.init_scale, "--json"]
        t0 = time.perf_counter()
        c0 = _cpu_children()
        proc = subprocess.run(cmd, capture_output=True, text=True, check=True)
        out = json.loads(proc.stdout)
        rows.append({"command": " ".join(["suspid"] + cmd[len(SUSPID):]), "successes": out["successes"], "total": out["total"],
                     "wall_s": time.perf_counter() - t0, "cpu_s": _cpu_children() - c0,
                     "mean_nfev": sum(e["nfev"] for e in out["experiments"]) / out["total"]})
    total = {"wall_s": time.perf_counter() - t_all, "cpu_s": _cpu_children() - cpu_all}
    if args.json:
        print(json.dumps({"runs": rows, "total": total}, indent=1))
    else:
        for r in rows:
            sys.stdout.write(f"{r['command']}: {r['successes']}/{r['total']} in {r['wall_s']:.1f} s wall, "
                             f"{r['cpu_s']:.1f} s CPU, {r['mean_nfev']:.0f} evaluations per experiment\n")
        sys.stdout.write(f"total: {total['wall_s']:.1f} s wall, {total['cpu_s']:.1f} s CPU "
                         f"(target < 120 s wall)\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
