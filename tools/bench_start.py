#!/usr/bin/env python3
"""Benchmark: identification with the data-driven start vs the given start alone.

Two parts, both printed side by side for the two paths in one run:

* ``timing`` (default): seconds per identification of the seed's designs (``suspid doe``
  rows) and of ``suspid identify`` on the Table 1 bump, with the data-driven start
  (``data``) and without it (``init``: the ``--init-scale`` start alone, the earlier
  behaviour), with the success count of each.
* ``--grid``: success counts of every design row for the models, costs, ``--init-scale``
  values and noise levels given (the study behind docs/performance.md's table; the noisy
  rows start at the ``--noise-scales`` init scales, 0.5 by default); with ``--compare``
  also for the ``init`` path.

Usage::

    python tools/bench_start.py [--models half4,quarter2] [--scales 0.1,10] [--ids 1,2,3]
    python tools/bench_start.py --grid [--models ...] [--costs sse,frobenius]
        [--scales 0.1,0.2,0.5,2,5,10] [--noise 0.1,0.2,0.3,0.4,0.5] [--noise-scales 0.5]
        [--compare] [--json]
    python tools/bench_start.py --data-only [--models ...] [--scales ...] [--noise ...]
        [--costs ...] [--no-bump] [--base DIR [--repeat K]]
    python tools/bench_start.py --estimate-only [--models ...] [--costs ...] [--scales ...]
        [--noise ...] [--ids ...] [--base DIR]

``--data-only --base DIR`` times the same cases in one run with this checkout and with the
code at ``DIR`` (e.g. ``git worktree add /tmp/base 84d56c2``; each case in a subprocess
with ``PYTHONPATH`` at the version, the two alternately), and prints before / after /
ratio side by side, in wall seconds and in CPU seconds (the process's own; on a shared
machine the steadier of the two). ``--repeat K`` runs every case K times per version
(alternately) and reports each version's fastest run.

``--estimate-only`` runs the record's estimate (``estimate_start``) alone on every design
row and prints, per row, the worst factor between an estimated value and the truth (and
which value), the estimate's output-error cost against the truth's, the bandwidth chosen
and the CPU seconds; with ``--base DIR`` the code at ``DIR`` (before) beside this one
(after), each version in a subprocess.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only cost here

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from scipy.stats import binom

from estimator.doe import runner
from estimator.doe.design import experiments
from estimator.doe.runner import Settings, measurement, run_design, start_parameters
from estimator.identify import (OutputErrorProblem, Parameters, estimate_start, fit,
                                fit_from_starts)
from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement
from suspid.models import get_model
from suspid.simulate import simulate

TABLE1 = dict(m1=275.0, k1=150000.0, c1=1120.0, m2=27.0, k2=310000.0, c2=3100.0)


def _floats(text: str) -> list[float]:
    return [float(s) for s in text.split(",") if s.strip()]


def doe_row(model: str, cost: str, scale: float, noise: float, data: bool,
            ids: list[int] | None) -> dict[str, Any]:
    """One design (or its rows ``ids``): successes, total and seconds per row."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = run_design(model, Settings(cost=cost, init_scale=scale, noise=noise,
                                     data_start=data), ids=ids)
    dt, cpu = time.perf_counter() - t0, time.process_time() - c0
    worst = max((e["max_rel_error"] or float("inf")) for e in out["experiments"])
    # rows reported a success (by the identifier, or by the study's rule) with a parameter
    # more than 10x from the truth
    false_ok = [e["id"] for e in out["experiments"]
                if (e.get("reported_success") or e["success"])
                and any(not 0.1 <= 1.0 + v <= 10.0 for v in e["rel_error"].values())]
    unflagged = [e["id"] for e in out["experiments"] if not e["success"] and e["identifiable"]
                 and not any("implausible" in w for w in e.get("warnings", []))]
    flagged = [e["id"] for e in out["experiments"] if not e["success"] and e["id"] not in unflagged]
    # the rule before the honest bands: inside value +- 3 (curvature) standard errors
    curvature_ok = sum(all(e["stderr"].get(k) is not None
                           and abs(e["identified"][k] - e["true"][k]) <= 3 * e["stderr"][k]
                           for k in e["rel_error"]) for e in out["experiments"])
    profiled = [e["id"] for e in out["experiments"]
                if "profile" in e.get("band_method", {}).values()]
    return {"model": model, "cost": cost, "init_scale": scale, "noise": noise,
            "failed_unflagged": unflagged, "failed_flagged": flagged, "profiled": profiled,
            "curvature_band_successes": curvature_ok,
            "path": "data" if data else "init", "successes": out["successes"],
            "total": out["total"], "s_per_row": dt / out["total"],
            "cpu_s_per_row": cpu / out["total"], "worst_rel": worst,
            "nfev_per_row": sum(e["nfev"] for e in out["experiments"]) / out["total"],
            "failed": [e["id"] for e in out["experiments"] if not e["success"]],
            "success_true_beyond_10x": false_ok,
            **({"band_coverage": out["band_coverage"]} if "band_coverage" in out else {})}


def estimate_rows(model: str, cost: str, scale: float, noise: float,
                  ids: list[int] | None) -> list[dict[str, Any]]:
    """``estimate_start`` alone on each design row: worst factor, costs, CPU seconds."""
    m = get_model(model)
    out = []
    for e in experiments(m):
        if ids and e.id not in ids:
            continue
        st = Settings(cost=cost, init_scale=scale, noise=noise)
        meas, _ = measurement(m, e, noise, st.seed + e.id)
        problem = OutputErrorProblem(m, meas, x0=e.x0, cost=cost)
        params = start_parameters(m, e, st)
        c0 = time.process_time()
        est = estimate_start(problem, params)
        cpu = time.process_time() - c0
        fac = {k: max(v / e.truth[k], e.truth[k] / v) if v > 0 else math.inf
               for k, v in est.values.items()}
        worst = max(fac, key=lambda k: fac[k]) if fac else None
        out.append({"model": model, "cost": cost, "init_scale": scale, "noise": noise,
                    "row": e.id, "worst": fac[worst] if worst else math.inf,
                    "worst_param": worst, "est_cost": est.cost,
                    "truth_cost": problem.normalized_ss(dict(e.truth)),
                    "bandwidth_hz": est.bandwidth_hz, "undetermined": est.undetermined,
                    "cpu_s": cpu})
    return out


def _estimate_side_by_side(a: argparse.Namespace) -> int:
    """``--estimate-only --base DIR``: every row's estimate with the code at ``DIR`` and this."""
    here = Path(__file__).resolve().parent.parent
    args = [sys.executable, str(Path(__file__).resolve()), "--estimate-only", "--json",
            "--models", a.models, "--costs", a.costs, "--scales", a.scales or "0.5,10",
            "--noise", a.noise or "0.5"] + (["--ids", a.ids] if a.ids else [])
    got = {}
    for label, root in (("before", Path(a.base).resolve()), ("after", here)):
        env = dict(os.environ, PYTHONPATH=str(root))
        out = subprocess.run(args, env=env, cwd="/tmp", capture_output=True, text=True,
                             check=True)
        got[label] = json.loads(out.stdout.strip().splitlines()[-1])
    w = sys.stdout.write
    w(f"{'case':34} {'row':>3} {'worst before':>18} {'after':>18} {'cost before':>11} "
      f"{'after':>7} {'truth':>7}\n")
    totals: dict[str, list[float]] = {}
    for b, n in zip(got["before"], got["after"]):
        case = f"{n['model']} {n['cost']} x{n['init_scale']:g} noise {n['noise']:g}"
        t = totals.setdefault(case, [0.0, 0.0, 0.0])
        t[0] += b["cpu_s"]
        t[1] += n["cpu_s"]
        t[2] += 1
        wb = f"{b['worst']:.3g} {b['worst_param']}"
        wn = f"{n['worst']:.3g} {n['worst_param']}"
        w(f"{case:34} {n['row']:3d} {wb:>18} {wn:>18} {b['est_cost']:11.4g} "
          f"{n['est_cost']:7.4g} {n['truth_cost']:7.4g}\n")
    for case, (cb, cn, k) in totals.items():
        w(f"{case:34} CPU s per estimate {cb / k:.3f} -> {cn / k:.3f}\n")
    return 0


def identify_bump(scale: float, data: bool) -> dict[str, Any]:
    """``suspid identify`` on the Table 1 bump (springs/dampers x ``scale``), no --init."""
    m = get_model("quarter2")
    truth = {k: v * (scale if k not in ("m1", "m2") else 1.0) for k, v in TABLE1.items()}
    t, road, x0 = make_scenario(m, "bump", duration=3.0, fs=1000.0, params=truth)
    sim = simulate(m, truth, t, road, x0)
    meas = Measurement(t=t, road=road, measured={c: sim[c] for c in
                                                 ("x1", "x2", "x1_dot", "x2_dot")})
    problem = OutputErrorProblem(m, meas)
    params = Parameters.for_model(m, fix={"m1": 275.0, "m2": 27.0})
    t0 = time.perf_counter()
    res = fit_from_starts(problem, params,
                          lambda s: fit(problem, s, polish=True, multistart=4)[0],
                          data_start=data, keep_init=not data)
    dt = time.perf_counter() - t0
    err = max(abs(res.params[k] / truth[k] - 1) for k in ("c1", "k1", "c2", "k2"))
    return {"case": f"identify bump x{scale:g}", "path": "data" if data else "init",
            "seconds": dt, "max_rel_error": err, "success": res.success, "nfev": res.nfev}


def _side_by_side(a: argparse.Namespace) -> int:
    """``--data-only --base DIR``: every case with the code at ``DIR`` and with this one."""
    here = Path(__file__).resolve().parent.parent
    args = [sys.executable, str(Path(__file__).resolve()), "--data-only", "--json", "--no-bump"]
    args += ["--ids", a.ids] if a.ids else []
    roots = {"before": Path(a.base).resolve(), "after": here}
    runs: dict[str, list[dict[str, Any]]] = {"before": [], "after": []}
    cases = [(m, c, s, n) for m in a.models.split(",") for c in a.costs.split(",")
             for s in _floats(a.scales or "0.5") for n in _floats(a.noise or "0")]
    order = 0
    for m, c, s, n in cases:
        best: dict[str, list[dict[str, Any]]] = {}
        for _ in range(max(a.repeat, 1)):
            # one case at a time, the two versions alternately and in alternating order,
            # so that a change of the machine's load hits both alike
            for label in (("before", "after") if order % 2 == 0 else ("after", "before")):
                env = dict(os.environ, PYTHONPATH=str(roots[label]))
                out = subprocess.run(args + ["--models", m, "--costs", c, "--scales", f"{s:g}",
                                             "--noise", f"{n:g}"], env=env, cwd="/tmp",
                                     capture_output=True, text=True, check=True)
                got = json.loads(out.stdout.strip().splitlines()[-1])
                if label in best:  # the fastest run of each row, wall and CPU alike
                    for r, g in zip(best[label], got):
                        for key in ("s_per_row", "cpu_s_per_row"):
                            if key in g:
                                r[key] = min(r.get(key, math.inf), g[key])
                else:
                    best[label] = got
            order += 1
        for label in runs:
            runs[label] += best[label]
    w = sys.stdout.write
    w(f"{'case':40} {'before s/id':>11} {'after s/id':>10} {'ratio':>6} {'CPU before':>10} "
      f"{'after':>6} {'ratio':>6} {'nfev before':>11} {'after':>6} {'ok before':>9} "
      f"{'after':>6}\n")
    for b, n in zip(runs["before"], runs["after"]):
        case = f"doe {n['model']} {n['cost']} x{n['init_scale']:g} noise {n['noise']:g}"
        # CPU seconds: a version without them (before they were recorded) shows nan
        cb, cn = b.get("cpu_s_per_row", math.nan), n.get("cpu_s_per_row", math.nan)
        w(f"{case:40} {b['s_per_row']:11.3f} {n['s_per_row']:10.3f} "
          f"{n['s_per_row'] / b['s_per_row']:6.2f} {cb:10.3f} {cn:6.3f} {cn / cb:6.2f} "
          f"{b['nfev_per_row']:11.0f} {n['nfev_per_row']:6.0f} "
          f"{b['successes']:>5}/{b['total']:<3} {n['successes']:>3}/{n['total']:<3}\n")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", action="store_true", help="success grid instead of timing")
    ap.add_argument("--models", default="quarter1,quarter2,half4")
    ap.add_argument("--costs", default="sse")
    ap.add_argument("--scales", default=None,
                    help="init scales (default 0.1,10 for timing, 0.1,0.2,0.5,2,5,10 for the "
                         "grid; an empty string for none)")
    ap.add_argument("--noise", default="", help="noise levels (grid; at init scale 0.5)")
    ap.add_argument("--noise-scales", default="0.5",
                    help="grid: init scales of the noisy rows (default 0.5)")
    ap.add_argument("--ids", default=None, help="design rows (timing; default all)")
    ap.add_argument("--compare", action="store_true", help="grid: also the init-only path")
    ap.add_argument("--data-only", action="store_true",
                    help="timing: the data-driven path only (to compare two versions of the "
                         "code: run once per version, e.g. with PYTHONPATH at an unpacked "
                         "`git archive` of the other)")
    ap.add_argument("--base", default=None,
                    help="--data-only: also time the code at this directory (before) and "
                         "print it side by side with this checkout (after)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="--base: runs of every case per version (the fastest is reported)")
    ap.add_argument("--no-bump", action="store_true",
                    help="--data-only: leave out the `identify bump` cases")
    ap.add_argument("--estimate-only", action="store_true",
                    help="the record's estimate alone on every design row (default scales "
                         "0.5,10, noise 0.5): worst factor from the truth, output-error "
                         "cost, CPU seconds; with --base side by side")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    models = [s for s in a.models.split(",") if s]
    costs = [s for s in a.costs.split(",") if s]
    ids = [int(s) for s in a.ids.split(",")] if a.ids else None
    rows: list[dict[str, Any]] = []
    w = sys.stdout.write
    if a.grid:
        scales = _floats("0.1,0.2,0.5,2,5,10" if a.scales is None else a.scales)
        cases = [(m, c, s, 0.0) for m in models for c in costs for s in scales]
        cases += [(m, c, s, n) for m in models for c in costs for s in _floats(a.noise_scales)
                  for n in _floats(a.noise)]
        for m, c, s, n in cases:
            for data in ([True, False] if a.compare else [True]):
                r = doe_row(m, c, s, n, data, ids)
                rows.append(r)
                if not a.json:
                    w(f"{m:9} {c:9} scale {s:<5g} noise {n:<4g} {r['path']:5} "
                      f"{r['successes']:>2}/{r['total']:<2} {r['s_per_row']:6.2f} s/row "
                      f"failed {r['failed']} (not flagged: {r['failed_unflagged']}) "
                      f"success-true>10x {r['success_true_beyond_10x']}"
                      + (f" | curvature band alone {r['curvature_band_successes']}/{r['total']}, "
                         f"profile bands in {len(r['profiled'])} rows, bands missed "
                         f"{r['band_coverage']['missed']}/{r['band_coverage']['bands']} "
                         f"(expected {r['band_coverage']['expected']:.2f}), outside the joint region "
                         f"{r['band_coverage']['joint_outside']}" if n > 0 else "")
                      + "\n")
                    sys.stdout.flush()
        cover = [r["band_coverage"] for r in rows if "band_coverage" in r]
        if cover and not a.json:
            # every noisy cell together: bands missed against the exact expectation, and the
            # rows outside their joint region (independent rows: a binomial count)
            n_b, k_b = sum(b["bands"] for b in cover), sum(b["missed"] for b in cover)
            n_r, k_r = (sum(b["joint_rows"] for b in cover),
                        sum(len(b["joint_outside"]) for b in cover))
            w(f"all noisy cells: {k_b} of {n_b} closed 3-sigma bands miss the truth (correct "
              f"bands miss {n_b * runner.JOINT_ALPHA:.2f} on average; misses within a row are "
              f"correlated); {k_r} of {n_r} rows outside their joint 3-sigma region (expected "
              f"{n_r * runner.JOINT_ALPHA:.2f}, P(>= {k_r}) = "
              f"{binom.sf(k_r - 1, n_r, runner.JOINT_ALPHA) if k_r else 1.0:.3f})\n")
    elif a.estimate_only and a.base:
        return _estimate_side_by_side(a)
    elif a.estimate_only:
        for m in models:
            for c in costs:
                for s in _floats(a.scales or "0.5,10"):
                    for n in _floats(a.noise or "0.5"):
                        got = estimate_rows(m, c, s, n, ids)
                        rows += got
                        if not a.json:
                            for r in got:
                                w(f"{f'{m} {c} x{s:g} noise {n:g}':34} {r['row']:3d} "
                                  f"worst {r['worst']:8.3g} {str(r['worst_param']):3} cost "
                                  f"{r['est_cost']:.4g} (truth {r['truth_cost']:.4g}) "
                                  f"{r['bandwidth_hz']:.3g} Hz {r['cpu_s']:.3f} s\n")
                            sys.stdout.flush()
    elif a.data_only and a.base:
        return _side_by_side(a)
    elif a.data_only:
        scales = _floats(a.scales or "0.1,10")
        noises = _floats(a.noise) or [0.0]
        for m in models:
            for c in costs:
                for s in scales:
                    for n in noises:
                        r = doe_row(m, c, s, n, True, ids)
                        rows.append(r)
                        if not a.json:
                            w(f"{f'doe {m} {c} x{s:g} noise {n:g}':40} {r['s_per_row']:8.3f} s/id "
                              f"{r['successes']:>3}/{r['total']:<3} {r['nfev_per_row']:8.0f} nfev/id\n")
                            sys.stdout.flush()
        for s in ([] if a.no_bump else [1.0, 5.0, 0.2]):
            r = identify_bump(s, True)
            rows.append(r)
            if not a.json:
                w(f"{r['case']:40} {r['seconds']:8.3f} s/id {str(r['success']):>7} "
                  f"{r['nfev']:8d} nfev/id max rel error {r['max_rel_error']:.1e}\n")
    else:
        scales = _floats(a.scales or "0.1,10")
        if not a.json:
            w(f"{'case':34} {'init s/id':>10} {'data s/id':>10} {'ratio':>6} "
              f"{'init ok':>8} {'data ok':>8}\n")
        for m in models:
            for c in costs:
                for s in scales:
                    old = doe_row(m, c, s, 0.0, False, ids)
                    new = doe_row(m, c, s, 0.0, True, ids)
                    rows += [old, new]
                    if not a.json:
                        w(f"{f'doe {m} {c} x{s:g}':34} {old['s_per_row']:10.3f} "
                          f"{new['s_per_row']:10.3f} {new['s_per_row'] / old['s_per_row']:6.2f} "
                          f"{old['successes']:>4}/{old['total']:<3} "
                          f"{new['successes']:>4}/{new['total']:<3}\n")
                        sys.stdout.flush()
        for s in (1.0, 5.0, 0.2):
            old, new = identify_bump(s, False), identify_bump(s, True)
            rows += [old, new]
            if not a.json:
                w(f"{old['case']:34} {old['seconds']:10.3f} {new['seconds']:10.3f} "
                  f"{new['seconds'] / old['seconds']:6.2f} {str(old['success']):>8} "
                  f"{str(new['success']):>8}   max rel error init {old['max_rel_error']:.1e}, "
                  f"data {new['max_rel_error']:.1e}\n")
    if a.json:
        json.dump(rows, sys.stdout)
        w("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
