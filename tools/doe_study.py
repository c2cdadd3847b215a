"""Reproduce the numbers and figures of ``docs/paper-reproduction.md``.

Usage (from the repository root)::

    python tools/doe_study.py ablation        [--out docs]   # half4 L27, what each step buys
    python tools/doe_study.py noise           [--out docs]   # §6.2 noise, CRLB, denoising
    python tools/doe_study.py identifiability [--out docs]   # scale ambiguity, minimal prior
    python tools/doe_study.py figures         [--out docs]   # target vs identified PNGs

Each writes ``<out>/data/<study>.json`` (and PNGs under ``<out>/figures/``) and prints a
summary. The designs themselves are ``suspid doe ...`` (see the doc).
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np


sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository: tools.*

from tools.doe_baseline import seed_identify  # noqa: E402
from estimator.doe.design import Experiment, experiments
from tools.doe_prior import prior_study, scale_ambiguity  # noqa: E402
from tools.doe_noise import monte_carlo  # noqa: E402
from estimator.doe.runner import (TOL, Settings, free_names, identify_staged, measurement,
                                  run_design, start_parameters)
from estimator.identify import IdentResult
from suspid.io.csvio import Measurement
from suspid.models import SuspensionModel, get_model
from suspid.models.base import FloatArray
from suspid.plots import plot_channels
from suspid.simulate import simulate


def _save(out: Path, name: str, obj: Any) -> Path:
    (out / "data").mkdir(parents=True, exist_ok=True)
    path = out / "data" / f"{name}.json"
    path.write_text(json.dumps(obj, indent=1, default=float) + "\n")
    return path


def _state_simulator(model: SuspensionModel, t: FloatArray,
                     x0: FloatArray) -> Callable[[Mapping[str, float]], FloatArray]:
    """The states of ``model`` from ``x0`` on ``t`` (no road) as columns, per parameter set."""

    def sim(p: Mapping[str, float]) -> FloatArray:
        out = simulate(model, p, t, None, x0)
        return np.column_stack([out[c] for c in model.state_names])

    return sim


def seed_port_design(model_name: str, cost: str, init_scale: float = 0.5) -> dict[str, Any]:
    """The design run with the seed's optimiser: fminsearch defaults on the raw cost.

    The exact simulator replaces ode45 here (only the optimiser is compared).
    """
    model = get_model(model_name)
    rows = []
    for e in experiments(model):
        meas, _ = measurement(model, e)
        Y = np.column_stack([meas.measured[c] for c in model.state_names])
        free = free_names(model, False)
        fixed = {k: v for k, v in e.truth.items() if k not in free}
        start = {k: init_scale * e.truth[k] for k in free}
        t = meas.t
        sim = _state_simulator(model, t, e.x0)
        t0 = time.perf_counter()
        p, res = seed_identify(model, Y, t, e.x0, fixed, start, cost, sim)
        rel = max(abs(p[k] - e.truth[k]) / e.truth[k] for k in free)
        rows.append({"id": e.id, "max_rel_error": rel, "success": rel <= TOL,
                     "nfev": int(res.nfev), "seconds": time.perf_counter() - t0})
    return {"successes": sum(r["success"] for r in rows), "total": len(rows), "experiments": rows}


def _summ(d: dict[str, Any], seconds: float) -> dict[str, Any]:
    ex = d["experiments"]
    return {"successes": d["successes"], "total": d["total"],
            "failed_ids": [e["id"] for e in ex if not e["success"]],
            "mean_nfev": float(np.mean([e["nfev"] for e in ex])),
            "seconds": seconds}


def ablation(out: Path) -> dict[str, Any]:
    """half4 L27 from 0.5x, both costs: seed port -> log coords -> restarts -> continuation."""
    ladder = {
        "seed_port_fminsearch": None,
        "log_coords_single_run": Settings(stages=(1.0,), restarts=0, step=0.3),
        "log_coords_restarts6": Settings(stages=(1.0,), restarts=6, step=0.3),
        "continuation_ours": Settings(),
    }
    res: dict[str, Any] = {}
    for cost in ("sse", "frobenius"):
        for name, s in ladder.items():
            t0 = time.perf_counter()
            if s is None:
                d = seed_port_design("half4", cost)
            else:
                d = run_design("half4", replace(s, cost=cost))
            res[f"{name}/{cost}"] = _summ(d, time.perf_counter() - t0)
            print(f"{name:>24} {cost:>9}: {d['successes']}/{d['total']} "
                  f"({time.perf_counter() - t0:.0f} s)", flush=True)
    for cost in ("sse", "frobenius"):
        t0 = time.perf_counter()
        d = run_design("half4", Settings(cost=cost, init_scale=0.75))
        res[f"continuation_ours_start0.75/{cost}"] = _summ(d, time.perf_counter() - t0)
        print(f"{'ours, start 0.75x':>24} {cost:>9}: {d['successes']}/{d['total']}", flush=True)
    _save(out, "ablation", res)
    return res


def noise(out: Path, seeds: int = 20, exp_id: int = 14) -> dict[str, Any]:
    """§6.2: half4 (masses fixed) at 0.1-0.5 sigma; CRLB; the L27 at 0.5 sigma."""
    res: dict[str, Any] = {"experiment": exp_id, "seeds": seeds, "mc": {}, "design": {}}
    for cost in ("sse", "frobenius"):
        for frac in (0.1, 0.3, 0.5):
            r = monte_carlo("half4", exp_id, Settings(cost=cost, noise=frac), seeds)
            r.pop("runs")
            res["mc"][f"{cost}/{frac}"] = r
            print(f"half4 exp {exp_id} {cost} {frac}: max {r['max_abs_overall']:.2%} "
                  f"ratio {min(r['ratio'].values()):.2f}-{max(r['ratio'].values()):.2f} "
                  f"coverage {r['coverage_3sigma']:.2f}", flush=True)
        r = monte_carlo("half4", exp_id, Settings(cost=cost, noise=0.5), seeds, weighted=True)
        r.pop("runs")
        res["mc"][f"{cost}/0.5/weighted"] = r
        print(f"half4 exp {exp_id} {cost} 0.5 weighted: max {r['max_abs_overall']:.2%} "
              f"ratio {min(r['ratio'].values()):.2f}-{max(r['ratio'].values()):.2f}", flush=True)
        d = run_design("half4", Settings(cost=cost, noise=0.5))
        mx = max(e["max_rel_error"] for e in d["experiments"])
        res["design"][cost] = {"successes": d["successes"], "total": d["total"],
                               "max_rel_error": mx,
                               "per_experiment_max": [e["max_rel_error"] for e in d["experiments"]]}
        print(f"half4 L27 {cost} 0.5 sigma: {d['successes']}/{d['total']} inside 3 sigma, "
              f"max error {mx:.2%}", flush=True)
    _save(out, "noise", res)
    return res


def identifiability(out: Path) -> dict[str, Any]:
    """Scale ambiguity and which single known parameter suffices (quarter2, half4)."""
    res: dict[str, Any] = {"scale": [scale_ambiguity(m, 14) for m in ("quarter1", "quarter2", "half4")],
                           "prior": []}
    cases = [("quarter1", []), ("quarter1", ["m"]),
             ("quarter2", []), ("quarter2", ["m1"]), ("quarter2", ["m2"]), ("quarter2", ["k2"]),
             ("half4", []), ("half4", ["m", "I", "m1", "m2"]), ("half4", ["m"]), ("half4", ["m1"]),
             ("half4", ["I"]), ("half4", ["k4"])]
    for model, known in cases:
        r = prior_study(model, 14, known)
        r.pop("identified")
        res["prior"].append(r)
        print(f"{model:>8} known {','.join(known) or '-':>12}: success {r['success']} max err "
              f"{r['max_rel_error']:.1e} identifiable {r['identifiable']} "
              f"min sv {r['min_singular_value']:.1e} common factor {r['common_factor']:.3f} "
              f"(spread {r['spread_about_common_factor']:.1e})", flush=True)
    _save(out, "identifiability", res)
    return res


def figures(out: Path, only: str | None = None) -> list[str]:
    """Seed-style target-vs-identified figures and the CRLB bar chart (``only``: one by name)."""
    figdir = out / "figures"
    figdir.mkdir(parents=True, exist_ok=True)
    written = []

    def fit_exp(model_name: str, exp_id: int, settings: Settings
                ) -> tuple[SuspensionModel, Experiment, Measurement, dict[str, FloatArray],
                           IdentResult, dict[str, FloatArray], float]:
        model = get_model(model_name)
        e = next(x for x in experiments(model) if x.id == exp_id)
        meas, clean = measurement(model, e, settings.noise, settings.seed + e.id)
        free = free_names(model, settings.free_masses)
        params = start_parameters(model, e, settings)
        res = identify_staged(model, meas, e.x0, params, settings)
        ident = simulate(model, res.params, meas.t, None, e.x0)
        err = max(abs(res.params[k] - e.truth[k]) / e.truth[k] for k in free)
        return model, e, meas, clean, res, ident, err

    specs = [
        ("quarter1_unrestricted_sse", "quarter1", 6,
         Settings(cost="sse", free_masses=True, mass_init_scale=1.0),
         "quarter1 L16 exp 6, mass free from the truth, c and k from 0.5x (seed Fig. 17)"),
        ("quarter1_restricted_sse", "quarter1", 6, Settings(cost="sse"),
         "quarter1 L16 exp 6, mass fixed (seed Fig. 19)"),
        ("quarter2_restricted_frobenius", "quarter2", 14, Settings(cost="frobenius"),
         "quarter2 L27 exp 14, masses fixed (seed Figs. 27-28)"),
        ("half4_restricted_sse_exp20", "half4", 20, Settings(cost="sse"),
         "half4 L27 exp 20, masses fixed, cost sse (seed Figs. 35-37)"),
        ("half4_noise05_frobenius", "half4", 14, Settings(cost="frobenius", noise=0.5),
         "half4 L27 exp 14, 0.5 sigma noise, cost frobenius (seed Figs. 44-46)"),
    ]
    names = [sp[0] for sp in specs] + ["half4_single_stage_sse_exp20", "half4_noise05_crlb"]
    if only is not None and only not in names:
        raise SystemExit(f"error: --only {only!r}: expected one of {', '.join(names)}")
    for fname, model_name, exp_id, s, title in specs:
        if only is not None and fname != only:
            continue
        model, e, meas, clean, res, ident, err = fit_exp(model_name, exp_id, s)
        series: dict[str, dict[str, np.ndarray]] = {}
        if s.noise > 0:
            series["measured (noisy)"] = meas.measured
            series["clean target"] = clean
            series["identified = denoised"] = ident
        else:
            series["target"] = clean
            series["identified"] = ident
        path = figdir / f"{fname}.png"
        plot_channels(model, meas.t, series, path, title=f"{title}: max parameter error {err:.2%}")
        written.append(str(path))
    # the failure the continuation fixes: single-stage fit of half4 exp 20
    if only in (None, "half4_single_stage_sse_exp20"):
        model, e, meas, clean, res, ident, err = fit_exp(
            "half4", 20, Settings(cost="sse", stages=(1.0,), restarts=6))
        path = figdir / "half4_single_stage_sse_exp20.png"
        plot_channels(model, meas.t, {"target": clean, "identified (single stage)": ident}, path,
                      title=f"half4 exp 20, single-stage Nelder-Mead from 0.5x: max parameter error {err:.0%}")
        written.append(str(path))
    # CRLB chart from the noise study if present
    data = out / "data" / "noise.json"
    if only in (None, "half4_noise05_crlb") and data.is_file():
        # matplotlib costs about 1 s to import and only this chart needs it (suspid.plots
        # loads it the same way)
        import matplotlib  # noqa: PLC0415

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt  # noqa: PLC0415

        nz = json.loads(data.read_text())
        fig, axes = plt.subplots(1, 2, figsize=(11, 3.6), sharey=True)
        for ax, cost in zip(axes, ("sse", "frobenius")):
            r = nz["mc"][f"{cost}/0.5"]
            names = r["free"]
            x = np.arange(len(names))
            ax.bar(x - 0.2, [100 * r["rms"][k] for k in names], 0.4, label="observed RMS error")
            ax.bar(x + 0.2, [100 * r["crlb"][k] for k in names], 0.4, label="Cramér-Rao bound")
            ax.set_xticks(x, names)
            ax.set_title(f"half4 exp {nz['experiment']}, 0.5 sigma, cost {cost}, {r['seeds']} seeds")
            ax.grid(alpha=0.3, axis="y")
        axes[0].set_ylabel("relative std (%)")
        axes[0].legend()
        fig.tight_layout()
        path = figdir / "half4_noise05_crlb.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(str(path))
    for w in written:
        print(w)
    return written


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("study", choices=["ablation", "noise", "identifiability", "figures"])
    ap.add_argument("--out", default="docs", help="output folder (default docs)")
    ap.add_argument("--seeds", type=int, default=20, help="noise realisations (noise study)")
    ap.add_argument("--only", default=None, metavar="NAME",
                    help="figures: regenerate one figure (its file name without .png)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    t0 = time.perf_counter()
    if args.study == "ablation":
        ablation(out)
    elif args.study == "noise":
        noise(out, seeds=args.seeds)
    elif args.study == "identifiability":
        identifiability(out)
    else:
        figures(out, args.only)
    sys.stderr.write(f"{args.study}: {time.perf_counter() - t0:.0f} s\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
