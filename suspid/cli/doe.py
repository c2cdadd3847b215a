"""``suspid doe``: run the seed's Taguchi designs (L16 for quarter1, L27 for quarter2/half4;
an L27 of the project's for full7). Each row is simulated, identified from ``--init-scale``
times the truth and scored: within 1 % of the truth noise-free, within the run's 3-sigma band
when noisy (``docs/paper-reproduction.md``).
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import asdict
from typing import TYPE_CHECKING, Any, Callable, TextIO

from threadpoolctl import threadpool_limits

from estimator.doe.design import DESIGNS, experiments, setup_record
from suspid.cli._can import add_config_option
from suspid.cli._common import print_json
from suspid.cli._config import load_config
from suspid.cli._lazy import lazy_names
from suspid.errors import UsageError
from suspid.models import get_model

if TYPE_CHECKING:
    from estimator.doe.runner import Settings, run_design
else:
    Settings, run_design = lazy_names("estimator.doe.runner", "Settings", "run_design")


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("doe", help="run the seed's Taguchi designs of experiments (L16/L27)",
                       description="Run the seed's design of experiments: L16-4 (Tables 3-4) for "
                                   "quarter1, L27-3 (Tables 5-6) for quarter2 and half4, and "
                                   "Table 5's L27-3 on the full car's left corners for full7. "
                                   "Each row "
                                   "is simulated, identified from --init-scale x the truth and "
                                   "scored (1 % of the truth noise-free, 3 sigma when noisy).")
    p.add_argument("--model", required=True, choices=list(DESIGNS),
                   help="the model whose seed design to run: "
                        + ", ".join(f"{m} ({d})" for m, d in DESIGNS.items()))
    p.add_argument("--cost", choices=["sse", "frobenius"], default="sse",
                   help="sse: squared position differences (seed cost 1); frobenius: Frobenius "
                        "norm over positions and velocities (seed cost 2); default sse")
    p.add_argument("--init-scale", type=float, default=0.5, metavar="S",
                   help="start every free parameter at S x its true value (default 0.5)")
    p.add_argument("--free-masses", action="store_true",
                   help="identify the masses (and pitch inertia) too; by default they are "
                        "fixed at the truth, as in the seed's restricted optimisation")
    p.add_argument("--mass-init-scale", type=float, default=None, metavar="M",
                   help="with --free-masses: start the masses (and pitch inertia) at M x their "
                        "true value instead of S (the seed's unrestricted runs: M = 1). With "
                        "every parameter at S the start is an exactly scaled copy of the truth, "
                        "which fits perfectly, so nothing moves")
    p.add_argument("--noise", type=float, default=0.0, metavar="FRACTION",
                   help="Gaussian noise std as a fraction of each measured channel's std "
                        "(seed §6.2 uses 0.1-0.5); default 0 (noise-free)")
    p.add_argument("--seed", type=int, default=0,
                   help="noise seed; experiment i uses SEED + i (default 0)")
    p.add_argument("--ids", default=None, metavar="I,J,...",
                   help="run only these experiment numbers (default: the whole design)")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    add_config_option(p, "doe")
    return p


def _parse_ids(text: str | None, total: int) -> list[int] | None:
    if text is None:
        return None
    try:
        ids = sorted({int(s) for s in text.split(",") if s.strip()})
    except ValueError:
        raise UsageError(f"--ids {text!r}: expected comma-separated experiment numbers") from None
    bad = [i for i in ids if not 1 <= i <= total]
    if bad or not ids:
        raise UsageError(f"--ids {text!r}: expected numbers between 1 and {total}")
    return ids


def progress_bar(stream: TextIO, total: int, label: str) -> Callable[[int, bool], None]:
    """A one-line progress bar on a text stream (stderr), redrawn with carriage returns:
    drawn at 0, then ``update(done, success)`` after each experiment."""
    t0 = time.perf_counter()
    ok = 0

    def update(done: int, success: bool) -> None:
        nonlocal ok
        ok += int(success)
        filled = int(28 * done / max(total, 1))
        stream.write(f"\r{label} [{'#' * filled}{'.' * (28 - filled)}] {done}/{total} "
                     f"ok {ok} {time.perf_counter() - t0:5.1f}s" + ("\n" if done >= total else ""))
        stream.flush()

    update(0, False)
    return update


def run(args: argparse.Namespace) -> int:
    # small matrices: BLAS threads only cost (docs/performance.md)
    threadpool_limits(limits=1, user_api="blas")
    model = get_model(args.model)
    if not (args.init_scale > 0 and args.init_scale < 1e6):
        raise UsageError(f"--init-scale: expected a number > 0, got {args.init_scale}")
    if not (0 <= args.noise < 10):
        raise UsageError(f"--noise: expected a fraction >= 0 (e.g. 0.5), got {args.noise}")
    total = len(experiments(model))
    ids = _parse_ids(args.ids, total)
    if args.mass_init_scale is not None and not args.free_masses:
        raise UsageError("--mass-init-scale: only with --free-masses (fixed masses are the truth)")
    tuning = load_config(args.config).table("doe")
    settings = Settings(cost=args.cost, init_scale=args.init_scale, free_masses=args.free_masses,
                        mass_init_scale=args.mass_init_scale, noise=args.noise, seed=args.seed,
                        data_start=tuning.get("data_start", True))
    if tuning.get("single_stage", False):
        settings.stages = (1.0,)
        settings.step = 0.3
        settings.restarts = 6
    if "restarts" in tuning:
        settings.restarts = tuning["restarts"]
    n = len(ids) if ids is not None else total
    bar = None
    if tuning.get("progress", False) or sys.stderr.isatty():
        bar = progress_bar(sys.stderr, n, f"doe {args.model} {args.cost}")
    t0 = time.perf_counter()
    out = run_design(model, settings, ids=ids,
                     progress=(lambda i, _n, o: bar(i, o.success)) if bar else None)
    seconds = time.perf_counter() - t0
    result: dict[str, Any] = {
        "design": out["design"], "experiments": out["experiments"],
        "successes": out["successes"], "total": out["total"],
        "success_beyond_10x": out["success_beyond_10x"],
        **({"in_joint_region": out["in_joint_region"]} if "in_joint_region" in out else {}),
        **({"band_coverage": out["band_coverage"]} if "band_coverage" in out else {}),
        "model": model.name, "cost": args.cost, "init_scale": args.init_scale,
        "free_masses": bool(args.free_masses), "mass_init_scale": args.mass_init_scale,
        "noise": args.noise,
        "success_rule": ("every free parameter within its 3-sigma band" if args.noise > 0
                         else "every identified parameter within 1 % of the truth"),
        "setup": setup_record(model, settings.horizon, settings.fs),
        "method": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(settings).items()},
        "seconds": round(seconds, 3),
    }
    if args.json:
        print_json(result)
    else:
        w = sys.stdout.write
        w(f"{DESIGNS[model.name]} {model.name} cost {args.cost} start {args.init_scale}x "
          f"{'free masses' if args.free_masses else 'masses fixed'} noise {args.noise}\n")
        w(f"{'exp':>4} {'success':>8} {'max rel error':>14} {'nfev':>6}\n")
        for e in out["experiments"]:
            mre = e["max_rel_error"]
            w(f"{e['id']:>4} {str(e['success']):>8} {mre if mre is not None else float('nan'):>14.3e} "
              f"{e['nfev']:>6}\n")
        w(f"successes {out['successes']}/{out['total']} in {seconds:.1f} s\n")
        if "in_joint_region" in out:
            w(f"truth inside the row's joint 3-sigma region: {out['in_joint_region']}/"
              f"{out['total']}\n")
        if "band_coverage" in out:
            b = out["band_coverage"]
            w(f"bands missing the truth: {b['missed']} of {b['bands']} (correct 3-sigma bands "
              f"miss {b['expected']:.2f} on average); rows outside their joint region: "
              f"{len(b['joint_outside'])} of {b['joint_rows']} (expected {b['joint_expected']:.2f}, "
              f"P(>= {len(b['joint_outside'])}) = {b['p_value']:.2f})\n")
        if out["success_beyond_10x"]:
            w(f"reported a success with a parameter more than 10x from the truth: rows "
              f"{out['success_beyond_10x']}\n")
    return 0
