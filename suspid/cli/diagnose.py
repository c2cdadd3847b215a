"""``suspid diagnose``: fit, trace the residual to a missing effect, augment and refit."""
from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from suspid.cli._args import add_fit_options, add_road_option, fit_inputs
from suspid.cli._format import num
from suspid.cli._common import (add_input_options, add_model_option, add_param_options,
                                assignment_warnings, print_json)
from suspid.cli._lazy import lazy_names
from suspid.cli.identify import parse_x0

if TYPE_CHECKING:
    from estimator.diagnose import diagnose
    from estimator.diagnose.plots import plot_evidence
    from estimator.diagnose.roadfree import diagnose_road_unknown
    from estimator.identify.roadfree import resolve_road
else:
    diagnose, = lazy_names("estimator.diagnose", "diagnose")
    plot_evidence, = lazy_names("estimator.diagnose.plots", "plot_evidence")
    diagnose_road_unknown, = lazy_names("estimator.diagnose.roadfree", "diagnose_road_unknown")
    resolve_road, = lazy_names("estimator.identify.roadfree", "resolve_road")


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("diagnose", help="find the effect a model lacks from its residual, add it, refit",
                       description="Fit the declared model (as identify), analyse the residual "
                                   "(RMS, Ljung-Box whiteness, cross-correlation, residual force "
                                   "against candidate effects), add the effect the evidence "
                                   "supports (coulomb_friction, asymmetric_damping, "
                                   "quadratic_damping, progressive_spring, bump_stop, "
                                   "tire_liftoff, sensor_delay, sensor_offset, and any effect "
                                   "an installed package registers under the entry-point "
                                   "group suspid.effects), refit by "
                                   "Nelder-Mead and report before/after. A record whose sample "
                                   "times jitter within a quarter step of a uniform grid is "
                                   "resampled onto it (cubic spline, with a warning); a gap is an "
                                   "error. See docs/closing-the-loop.md.")
    add_model_option(p)
    add_input_options(p, "diagnose")
    add_param_options(p)
    add_fit_options(
        p, restarts=3,
        cost="sse: sum of squared position differences (seed cost 1); frobenius: "
             "Frobenius norm over all measured channels (seed cost 2)",
        maxfev="evaluation budget of every fit diagnose makes: the baseline fit (and, for a "
               "quarter car seen from the body, the fit from its twin), the linear refit on every "
               "channel, each candidate effect's refit and its reference fit; Nelder-Mead and "
               "Levenberg-Marquardt evaluations together, Jacobians included (default: each fit's "
               "own budget); restarts, further starts, the polish and the initial state of the "
               "baseline fit are the --config file's [fit] table")
    add_road_option(p)
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.add_argument("--plot", metavar="PNG", default=None,
                   help="write the evidence figure (residuals before/after, autocorrelation, "
                        "residual force against the chosen effect's regressor, candidate scores)")
    return p


def run(args: argparse.Namespace) -> int:
    """Run ``suspid diagnose`` (JSON or text on stdout, warnings on stderr); exit status 0."""
    model, params, meas, frames = fit_inputs(args, "diagnose")
    road, meas, road_warnings = resolve_road(model, meas, args.road)
    if road == "unknown":
        out = diagnose_road_unknown(model, meas, params).to_json()
        if args.plot:
            road_warnings.append("--plot: the evidence figure is drawn for a measured or zero "
                                 "road only; not written")
    else:
        res = diagnose(model, meas, params, cost=args.cost, x0=parse_x0(args.x0, model.n_states),
                       restarts=args.restarts, maxfev=args.maxfev, polish=args.polish,
                       multistart=args.multistart)
        out = res.to_json()
        out["road"] = road
        if args.plot:
            plot_evidence(res, res.record or meas, args.plot)
    out["warnings"] = assignment_warnings(args, model) + road_warnings + list(out["warnings"])
    if frames is not None:
        out["frames"] = frames
    if args.json:
        print_json(out)
    else:
        w = sys.stdout.write
        eff = out["effect"]
        sites = out["evidence"].get("effect_sites")
        w(f"model {model.name}: effect {eff['name'] if eff else 'none'}"
          + (f" ({', '.join(sites)})" if eff and sites else "") + "\n")
        if eff and eff["params"]:
            w("  effect parameters: " + ", ".join(f"{k}={num(v, 4)}" for k, v in eff["params"].items())
              + "\n")
        w(f"  {out['evidence']['verdict']}\n")
        rows = [(k, out["baseline"]["params"][k], out["augmented"]["params"][k], ".6g")
                for k in out["baseline"]["params"]]
        rows += [(f"rms {c}", out["baseline"]["rms_residual"][c], out["augmented"]["rms_residual"][c], ".4g")
                 for c in out["baseline"]["rms_residual"]]
        rows.append(("cost", out["baseline"]["cost"], out["augmented"]["cost"], ".6g"))
        width = max(8, *(len(r[0]) for r in rows))
        w(f"  {'':>{width}} {'baseline':>14} {'augmented':>14}\n")
        for label, before, after, fmt in rows:
            w(f"  {label:>{width}} {before:>14{fmt}} {after:>14{fmt}}\n")
    for msg in out["warnings"]:
        sys.stderr.write(f"warning: {msg}\n")
    return 0
