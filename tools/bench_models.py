#!/usr/bin/env python3
"""Benchmark: identification accuracy and speed per model, side by side.

For every model (default ``half4`` and ``full7``): noise-free ISO 8608 records (class C,
40 km/h, 4 s at 500 Hz, positions and velocities of every coordinate) for ``--seeds``
road seeds; the model's ``known`` parameters (masses, inertias, geometry) fixed, every other
parameter started at 0.5x its true value; both costs. Prints per model and cost the CPU
time per fit, the evaluations, the largest relative error and how many fits are within
1 % of the truth, and the CPU ratio of each model to the first.

Usage::

    python tools/bench_models.py [--models half4 full7] [--seeds 3] [--json]
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from estimator.identify import OutputErrorProblem, Parameters, fit
from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement
from suspid.models import get_model
from suspid.simulate import simulate


def run(name: str, cost: str, seed: int) -> dict[str, float]:
    """One noise-free fit: CPU seconds, evaluations, largest relative error."""
    m = get_model(name)
    truth = m.defaults()
    t, road, x0 = make_scenario(m, "iso8608", duration=4.0, fs=500.0, params=truth, v_kmh=40,
                                seed=seed)
    out = simulate(m, truth, t, road, x0)
    chans = list(m.coords) + [f"{c}_dot" for c in m.coords]
    meas = Measurement(t=t, road=road, measured={c: out[c] for c in chans}, source="bench")
    free = [k for k in m.param_names if k not in m.known]
    params = Parameters.for_model(m, fix={k: truth[k] for k in m.known},
                                  init={k: 0.5 * truth[k] for k in free})
    c0 = time.process_time()
    res, _ = fit(OutputErrorProblem(m, meas, cost=cost), params)
    cpu = time.process_time() - c0
    err = max(abs(res.params[k] / truth[k] - 1.0) for k in free)
    return {"cpu_s": cpu, "nfev": float(res.nfev), "max_rel_error": err, "n_free": float(len(free))}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", nargs="+", default=["half4", "full7"])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args()
    rows = []
    for cost in ("sse", "frobenius"):
        for name in args.models:
            runs = [run(name, cost, s) for s in range(args.seeds)]
            rows.append({"model": name, "cost": cost, "n_free": int(runs[0]["n_free"]),
                         "cpu_s_per_fit": float(np.mean([r["cpu_s"] for r in runs])),
                         "nfev_per_fit": float(np.mean([r["nfev"] for r in runs])),
                         "max_rel_error": max(r["max_rel_error"] for r in runs),
                         "within_1pct": sum(r["max_rel_error"] < 0.01 for r in runs),
                         "fits": len(runs)})
    for r in rows:
        first = next(x for x in rows if x["cost"] == r["cost"])
        r["cpu_ratio"] = r["cpu_s_per_fit"] / first["cpu_s_per_fit"]
    if args.json:
        print(json.dumps({"rows": rows}, indent=1))
    else:
        for r in rows:
            sys.stdout.write(f"{r['model']:>8} {r['cost']:>9}: {r['n_free']:2d} free, "
                             f"{r['within_1pct']}/{r['fits']} within 1 %, max error "
                             f"{r['max_rel_error']:.1e}, {r['cpu_s_per_fit']:.2f} s CPU and "
                             f"{r['nfev_per_fit']:.0f} evaluations per fit "
                             f"({r['cpu_ratio']:.1f}x {args.models[0]})\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
