"""Time one command line under two versions of the code, alternately, in one run.

Usage::

    python tools/bench_ab.py --base DIR [--repeat K] [--label NAME] -- suspid doe --model quarter2 --json

Runs the command K times per version (default 3), before (``PYTHONPATH=DIR``, e.g. a
``git archive`` or ``git worktree add`` of the older commit) and after (this checkout)
alternately, each in a fresh process of this interpreter (a leading ``suspid`` becomes
``python -m suspid``). Prints each version's fastest and median wall time and its CPU time
(user + system of the child, steadier on a shared machine), and the after/before ratio of
the medians. With ``--check KEY`` the command's stdout is read as JSON and ``KEY``'s value
printed per run (e.g. ``successes``), so results can be compared as well as times.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _once(cmd: list[str], path: Path, check: str | None) -> tuple[float, float, object]:
    env = {**os.environ, "PYTHONPATH": str(path)}
    c0, t0 = _cpu(), time.perf_counter()
    out = subprocess.run(cmd, cwd=path, env=env, capture_output=True, text=True)
    wall, cpu = time.perf_counter() - t0, _cpu() - c0
    if out.returncode != 0:
        raise SystemExit(f"{path}: exit {out.returncode}: {out.stderr.strip()[-400:]}")
    value: object = None
    if check:
        value = json.loads(out.stdout)
        for key in check.split("."):
            value = value[key]  # type: ignore[index]
    return wall, cpu, value


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", required=True, type=Path, help="checkout of the code before")
    ap.add_argument("--repeat", type=int, default=3, help="runs per version (default 3)")
    ap.add_argument("--label", default=None, help="name printed for the command")
    ap.add_argument("--check", default=None, metavar="KEY",
                    help="JSON key (dotted) of the command's output to print per run")
    ap.add_argument("command", nargs=argparse.REMAINDER, help="-- then the command line")
    args = ap.parse_args()
    cmd = [c for c in args.command if c != "--"] if args.command[:1] == ["--"] else args.command
    if not cmd:
        ap.error("no command given")
    cmd = [sys.executable, "-m", "suspid", *cmd[1:]] if cmd[0] == "suspid" else \
        [sys.executable if cmd[0] == "python" else cmd[0], *cmd[1:]]
    runs: dict[str, list[tuple[float, float, object]]] = {"before": [], "after": []}
    for _ in range(args.repeat):
        runs["before"].append(_once(cmd, args.base.resolve(), args.check))
        runs["after"].append(_once(cmd, ROOT, args.check))
    label = args.label or " ".join(args.command).lstrip("- ")
    print(label)
    med = {}
    for name, rs in runs.items():
        walls, cpus = [r[0] for r in rs], [r[1] for r in rs]
        med[name] = statistics.median(walls)
        vals = f"  {args.check}: {[r[2] for r in rs]}" if args.check else ""
        print(f"  {name:6s} wall best {min(walls):7.3f} s  median {med[name]:7.3f} s  "
              f"CPU median {statistics.median(cpus):7.3f} s{vals}")
    print(f"  after/before (median wall) {med['after'] / med['before']:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
