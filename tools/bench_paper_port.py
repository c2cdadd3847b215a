#!/usr/bin/env python3
"""Benchmark (issue 2): a paper-faithful port of the seed's MATLAB tool vs suspid.

Data: seed Table 1 quarter car (m1 = 275 kg, c1 = 1120 N s/m, k1 = 150 kN/m, m2 = 27 kg,
c2 = 3100 N s/m, k2 = 310 kN/m) over the seed's speed bump (0.1 m x 3 m at 20 km/h),
3 s at 1 kHz, positions and velocities measured, simulated exactly by suspid. Both
identify c1, k1, c2, k2 with the masses fixed, starting at 0.5x the truth, cost ``sse``.

* reference: RK45 at ode45's default RelTol 1e-3 / AbsTol 1e-6 on the same ``model.rhs``
  with the analytic bump as road, plus Nelder–Mead with fminsearch's defaults in raw
  coordinates (``tools.doe_baseline``). The seed's known zero initial state.
* suspid in-process: ``OutputErrorProblem`` + ``fit`` exactly as ``suspid identify`` runs
  them (initial state estimated by variable projection).
* suspid end to end: ``suspid identify ... --json`` as a subprocess, process start
  included.

Usage::

    python tools/bench_paper_port.py [--repeat 3] [--ref-maxfev N] [--json]

Prints both answers, their largest relative difference and the time ratios.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits


sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository: tools.*

from tools.doe_baseline import ode45, seed_identify  # noqa: E402
from estimator.identify import OutputErrorProblem, Parameters, fit
from suspid.excitation import bump_profile, make_scenario
from suspid.io.csvio import read_measurement, write_measurement
from suspid.models import get_model
from suspid.simulate import simulate

#: the console script of the running interpreter's environment (as a user runs it), or
#: ``python -m suspid`` when it is not installed as a script
SUSPID = ([str(Path(sys.executable).with_name("suspid"))]
          if Path(sys.executable).with_name("suspid").exists() else [sys.executable, "-m", "suspid"])

TABLE1 = {"m1": 275.0, "c1": 1120.0, "k1": 150000.0, "m2": 27.0, "c2": 3100.0, "k2": 310000.0}
FREE = ("c1", "k1", "c2", "k2")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="timed repetitions of suspid (best of)")
    ap.add_argument("--ref-maxfev", type=int, default=None,
                    help="evaluation budget of the reference (default fminsearch's 200 x 4)")
    ap.add_argument("--duration", type=float, default=3.0, help="record length (s)")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args()
    if "OPENBLAS_NUM_THREADS" not in os.environ:  # a user's setting wins
        threadpool_limits(limits=1, user_api="blas")  # small matrices: threads only cost here (in this process only)

    model = get_model("quarter2")
    t, road, x0 = make_scenario(model, "bump", duration=args.duration, fs=1000.0, params=TABLE1)
    clean = simulate(model, TABLE1, t, road, x0)
    chans = ["x1", "x2", "x1_dot", "x2_dot"]
    tmp = Path(tempfile.mkdtemp(prefix="suspid_bench_"))
    csv = tmp / "bump_table1.csv"
    write_measurement(csv, t, {"r": road["r"], "r_dot": road["r_dot"], **{c: clean[c] for c in chans}})
    meas = read_measurement(csv, model)
    start = {k: 0.5 * TABLE1[k] for k in FREE}
    fixed = {"m1": TABLE1["m1"], "m2": TABLE1["m2"]}

    # --- paper-faithful reference -------------------------------------------------
    def road_fn(tt: float) -> np.ndarray:
        r, rd = bump_profile(np.array([tt]), 0.1, 3.0, 20.0, 0.5)
        return np.array([r[0], rd[0]])

    Y = np.column_stack([meas.measured[c] for c in chans])
    t0 = time.perf_counter()
    c0 = time.process_time()
    ref_p, ref_res = seed_identify(model, Y, meas.t, np.zeros(4), fixed, start, "sse",
                                   lambda p: ode45(model, p, meas.t, np.zeros(4), road_fn),
                                   maxfev=args.ref_maxfev)
    t_ref = time.perf_counter() - t0
    cpu_ref = time.process_time() - c0

    # --- suspid in-process ----------------------------------------------------------
    times, cpus = [], []
    for _ in range(max(args.repeat, 1)):
        t0 = time.perf_counter()
        c0 = time.process_time()
        m2 = read_measurement(csv, model)
        params = Parameters.for_model(model, fix=fixed, init=start)
        res, _ = fit(OutputErrorProblem(model, m2, cost="sse"), params, polish=True)  # as the CLI
        times.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    t_fast = min(times)
    cpu_fast = min(cpus)

    # --- suspid end to end ------------------------------------------------------------
    cmd = [*SUSPID, "identify", "--model", "quarter2", "--input", str(csv), "--cost", "sse",
           "--fix", "m1=275", "--fix", "m2=27"] + [f"--init={k}={v}" for k, v in start.items()] + ["--json"]
    e2e = []
    out = {}
    env = dict(os.environ)  # run the CLI as a user would: no thread setting of ours
    for _ in range(max(args.repeat, 1)):
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, check=True, env=env)
        e2e.append(time.perf_counter() - t0)
        out = json.loads(proc.stdout)
    t_e2e = min(e2e)

    def rel(a: dict, b: dict) -> float:
        return max(abs(a[k] - b[k]) / abs(b[k]) for k in FREE)

    report = {
        "data": {"samples": int(meas.t.size), "duration_s": args.duration, "fs_hz": 1000.0},
        "reference": {"params": {k: ref_p[k] for k in FREE}, "nfev": int(ref_res.nfev),
                      "status": int(ref_res.status), "message": str(ref_res.message),
                      "seconds": t_ref, "max_rel_error_vs_truth": rel(ref_p, TABLE1)},
        "suspid": {"params": {k: res.params[k] for k in FREE}, "nfev": res.nfev,
                   "seconds": t_fast, "max_rel_error_vs_truth": rel(res.params, TABLE1)},
        "suspid_cli": {"params": {k: out["params"][k] for k in FREE}, "seconds": t_e2e},
        "answers_max_rel_diff": rel(res.params, ref_p),
        "cli_vs_inprocess_max_rel_diff": rel(out["params"], res.params),
        "speedup_inprocess": t_ref / t_fast,
        "speedup_inprocess_cpu": cpu_ref / cpu_fast,
        "speedup_end_to_end": t_ref / t_e2e,
        "command": " ".join(cmd),
    }
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        w = sys.stdout.write
        w(f"data: Table 1 quarter car, speed bump, {meas.t.size} samples\n")
        w(f"{'':>8} {'truth':>12} {'reference':>12} {'suspid':>12}\n")
        for k in FREE:
            w(f"{k:>8} {TABLE1[k]:>12.6g} {ref_p[k]:>12.6g} {res.params[k]:>12.6g}\n")
        w(f"reference: {t_ref:.2f} s wall, {cpu_ref:.2f} s CPU, {ref_res.nfev} evaluations "
          f"({ref_res.message})\n")
        w(f"suspid in-process: {t_fast * 1e3:.1f} ms wall, {cpu_fast * 1e3:.1f} ms CPU, "
          f"{res.nfev} evaluations\n")
        w(f"suspid identify (subprocess, process start included): {t_e2e * 1e3:.0f} ms\n")
        w(f"answers differ by at most {report['answers_max_rel_diff']:.2e} (relative)\n")
        w(f"speed-up in-process {report['speedup_inprocess']:.0f}x wall "
          f"({report['speedup_inprocess_cpu']:.0f}x CPU), end to end {report['speedup_end_to_end']:.0f}x\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
