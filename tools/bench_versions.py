#!/usr/bin/env python3
"""Benchmark: time per identification of this checkout against another version, side by side.

Runs the cases the start-free identification is measured on, each once with the code at
``--base DIR`` (e.g. ``git worktree add /tmp/base 876be91``, the version before the
data-driven start) and once with this checkout, alternately and each in its own process
(``PYTHONPATH`` at the version), and prints CPU seconds per identification (the process's
own, which a shared machine's load distorts least), wall seconds, evaluations and
successes of both:

* ``suspid doe`` designs (library call ``run_design``, rows ``--ids`` or all) for every
  model, cost and ``--init-scale`` given, noise-free, and at every ``--noise`` level from
  ``--noise-scale`` (0.5, the designs' default start);
* ``suspid identify`` with no ``--init`` on the seed's Table 1 speed bump (3 s at 1 kHz,
  positions and velocities, masses fixed), its springs and dampers x1, x5 (stiff) and
  x0.2 (soft); the record is written by this checkout's simulator and read by both
  versions' CLI (called in-process: the interpreter's start is not timed, the
  subcommand's own imports are).

Only the library calls both versions have are used (``run_design(model, Settings(cost,
init_scale, noise), ids)``, ``suspid.cli.main``), so the base can be any version since
the seed's designs landed.

Usage::

    python tools/bench_versions.py --base DIR [--models quarter1,quarter2,half4]
        [--costs sse,frobenius] [--scales 0.1,0.2,0.5,2,5,10] [--noise 0.1,0.5]
        [--ids 1,2,3] [--repeat N] [--no-identify] [--json]

``--repeat N`` runs every case N times per version (alternating) and keeps each version's
least CPU and wall time: on a shared machine a run is only ever slowed down, so the
minimum is the steadiest estimate (the evaluations and successes are the same each time).
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only cost here

import argparse
import contextlib
import io
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

#: the seed's Table 1 quarter car
TABLE1 = dict(m1=275.0, k1=150000.0, c1=1120.0, m2=27.0, k2=310000.0, c2=3100.0)
BUMP_SCALES = (1.0, 5.0, 0.2)


def _floats(text: str) -> list[float]:
    return [float(s) for s in text.split(",") if s.strip()]


def _worker_doe(model: str, cost: str, scale: float, noise: float, ids: str | None) -> dict[str, Any]:
    """One design with the version on ``sys.path``: CPU, wall, evaluations, successes."""
    from estimator.doe.runner import Settings, run_design

    rows = [int(s) for s in ids.split(",")] if ids else None
    t0, c0 = time.perf_counter(), time.process_time()
    out = run_design(model, Settings(cost=cost, init_scale=scale, noise=noise), ids=rows)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    n = out["total"]
    return {"wall_per_id": wall / n, "cpu_per_id": cpu / n, "successes": out["successes"],
            "total": n, "nfev_per_id": sum(e["nfev"] for e in out["experiments"]) / n}


def _worker_identify(csv: str) -> dict[str, Any]:
    """``suspid identify`` (no ``--init``) on ``csv`` with the version on ``sys.path``."""
    from suspid.cli import main

    buf = io.StringIO()
    argv = ["identify", "--model", "quarter2", "--input", csv, "--fix", "m1=275",
            "--fix", "m2=27", "--json"]
    t0, c0 = time.perf_counter(), time.process_time()
    with contextlib.redirect_stdout(buf):
        rc = main(argv)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    res = json.loads(buf.getvalue())
    return {"wall_per_id": wall, "cpu_per_id": cpu, "rc": rc, "success": bool(res["success"]),
            "nfev": res["nfev"], "params": res["params"]}


def _bump_csv(scale: float, folder: Path) -> tuple[Path, dict[str, float]]:
    """The Table 1 bump with springs and dampers x ``scale``: ``suspid simulate``'s CSV."""
    truth = {k: v * (1.0 if k in ("m1", "m2") else scale) for k, v in TABLE1.items()}
    path = folder / f"bump_x{scale:g}.csv"
    cmd = [sys.executable, "-m", "suspid", "simulate", "--model", "quarter2", "--scenario",
           "bump", "--duration", "3", "--fs", "1000", "--channels", "x1,x2,x1_dot,x2_dot",
           "--out", str(path)]
    for k, v in truth.items():
        cmd += ["--param", f"{k}={v:.17g}"]
    subprocess.run(cmd, check=True, capture_output=True,
                   env=dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parent.parent)))
    return path, truth


def _run(root: Path, argv: list[str]) -> dict[str, Any]:
    env = dict(os.environ, PYTHONPATH=str(root))
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), *argv], env=env,
                         cwd="/tmp", capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"error: {root}: {' '.join(argv)} failed: "
                         f"{out.stderr.strip().splitlines()[-1:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", help="checkout of the version to compare with")
    ap.add_argument("--models", default="quarter1,quarter2,half4")
    ap.add_argument("--costs", default="sse,frobenius")
    ap.add_argument("--scales", default="0.1,0.2,0.5,2,5,10")
    ap.add_argument("--noise", default="0.1,0.2,0.3,0.4,0.5")
    ap.add_argument("--noise-scale", type=float, default=0.5)
    ap.add_argument("--ids", default=None, help="design rows (default all)")
    ap.add_argument("--repeat", type=int, default=1, help="runs per case and version (least time kept)")
    ap.add_argument("--no-identify", action="store_true")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--worker", nargs="+", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        if a.worker[0] == "doe":
            m, c, s, n = a.worker[1:5]
            got = _worker_doe(m, c, float(s), float(n), a.ids)
        else:
            got = _worker_identify(a.worker[1])
        print(json.dumps(got))
        return 0
    if not a.base:
        ap.error("--base DIR is required")
    roots = {"before": Path(a.base).resolve(), "after": Path(__file__).resolve().parent.parent}
    cases: list[tuple[str, list[str], dict[str, float] | None]] = []
    for m in a.models.split(","):
        for c in a.costs.split(","):
            for s in _floats(a.scales):
                cases.append((f"doe {m} {c} x{s:g}", ["--worker", "doe", m, c, f"{s:g}", "0"],
                              None))
            for n in _floats(a.noise):
                cases.append((f"doe {m} {c} x{a.noise_scale:g} noise {n:g}",
                              ["--worker", "doe", m, c, f"{a.noise_scale:g}", f"{n:g}"], None))
    tmp = tempfile.TemporaryDirectory()
    if not a.no_identify:
        for s in BUMP_SCALES:
            path, truth = _bump_csv(s, Path(tmp.name))
            cases.append((f"identify bump x{s:g}", ["--worker", "identify", str(path)], truth))
    rows = []
    for i, (label, args, truth) in enumerate(cases):
        args = args + (["--ids", a.ids] if a.ids and args[1] == "doe" else [])
        got: dict[str, dict[str, Any]] = {}
        for rep in range(max(a.repeat, 1)):
            for version in (("before", "after") if (i + rep) % 2 == 0 else ("after", "before")):
                run = _run(roots[version], args)
                if version in got:
                    for k in ("cpu_per_id", "wall_per_id"):
                        run[k] = min(run[k], got[version][k])
                got[version] = run
        for version in ("before", "after"):
            if truth is not None:  # identify: success = the truth to 1e-6
                res = got[version]
                res["error"] = max(abs(res["params"][k] / truth[k] - 1)
                                   for k in ("c1", "k1", "c2", "k2"))
                res["successes"], res["total"] = int(res["error"] < 1e-6), 1
                res["nfev_per_id"] = res["nfev"]
                del res["params"]
        rows.append({"case": label, **got})
        if not a.json:
            b, n = got["before"], got["after"]
            print(f"{label:34} CPU {b['cpu_per_id']:7.3f} -> {n['cpu_per_id']:7.3f} s/id "
                  f"({n['cpu_per_id'] / b['cpu_per_id']:5.2f}x)  wall {b['wall_per_id']:7.3f} -> "
                  f"{n['wall_per_id']:7.3f}  nfev {b['nfev_per_id']:7.0f} -> {n['nfev_per_id']:7.0f}  "
                  f"ok {b['successes']}/{b['total']} -> {n['successes']}/{n['total']}", flush=True)
    if a.json:
        print(json.dumps(rows, indent=1))
    tmp.cleanup()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
