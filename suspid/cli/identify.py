"""``suspid identify``: fit a model's parameters to a measurement by Nelder–Mead."""
from __future__ import annotations

import argparse
import math
import sys
from typing import TYPE_CHECKING

from suspid.cli._args import add_fit_options, add_road_option, fit_inputs
from suspid.cli._format import num
from suspid.cli._common import (parse_state, add_input_options, add_model_option, add_param_options,
                                print_json, assignment_warnings)
from suspid.cli._lazy import lazy_names
from suspid.models.base import FloatArray

if TYPE_CHECKING:
    from estimator.identify import OutputErrorProblem
    from estimator.identify.record import identify_record
    from estimator.identify.roadfree import fit_road_unknown, resolve_road
    from suspid.plots import plot_comparison
else:
    OutputErrorProblem, = lazy_names("estimator.identify", "OutputErrorProblem")
    identify_record, = lazy_names("estimator.identify.record", "identify_record")
    fit_road_unknown, resolve_road = lazy_names("estimator.identify.roadfree", "fit_road_unknown",
                                                "resolve_road")
    plot_comparison, = lazy_names("suspid.plots", "plot_comparison")


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("identify", help="identify suspension parameters from a measurement",
                       description="Identify masses, springs and dampers from a measurement CSV or "
                                   "CAN log by Nelder–Mead in log coordinates, with standard errors "
                                   "and an identifiability verdict.")
    add_model_option(p)
    add_input_options(p, "identify")
    add_param_options(p)
    add_fit_options(
        p, restarts=6,
        cost="sse: sum of squared position differences (seed cost 1); frobenius: Frobenius norm "
             "of measured-minus-simulated over all measured channels (seed cost 2)",
        maxfev="evaluation budget of each fit over all its restarts, further starts and "
               "polish; the fits from the data-driven start, from --init/the defaults "
               "and from the quarter car's twin each have their own, and nfev reports "
               "their sum (default: 1200 per free parameter shared by every fit of the "
               "record, further starts ending once one returns to the best cost); "
               "restarts, further starts, polish, the data-driven start and the "
               "initial state are the --config file's [fit] table",
        offset="a constant offset in the road column(s) or in one position channel "
               "(a sensor zero not at the rest position; estimated at the data-driven "
               "start as extra linear unknowns, found when it is most of the misfit): "
               "remove: subtract it and fit the corrected record (default); keep: fit "
               "the record as it is (slow: every further start chases the offset's "
               "misfit); either way a warning names it")
    add_road_option(p)
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.add_argument("--plot", metavar="PNG", default=None,
                   help="write the seed-style comparison (measured vs identified) to this PNG")
    return p


def parse_x0(text: str, n: int) -> str | FloatArray:
    """``[fit] x0``: ``estimate``, ``rest`` or ``n`` comma-separated finite numbers."""
    if text in ("estimate", "rest"):
        return text
    return parse_state(text, n, "fit.x0")


def run(args: argparse.Namespace) -> int:
    model, params, meas, frames = fit_inputs(args, "identify")
    x0 = parse_x0(args.x0, model.n_states)
    road, meas, road_warnings = resolve_road(model, meas, args.road)
    if road == "unknown":
        result = fit_road_unknown(model, meas, params)
    else:
        problem = OutputErrorProblem(model, meas, cost=args.cost, x0=x0)
        result, fitted = identify_record(
            problem, params, restarts=args.restarts, maxfev=args.maxfev, polish=args.polish,
            multistart=args.multistart, data_start=args.data_start,
            keep_init=bool(args.init) or not args.data_start, offset=args.offset)
        result.road = road
    if frames is not None:
        result.frames = frames
    result.warnings[:0] = assignment_warnings(args, model) + road_warnings
    if args.plot and road != "unknown":
        plot_comparison(model, fitted.meas, result, args.plot)  # the record as fitted
    if args.json:
        print_json(result.to_json())
    else:
        w = sys.stdout.write
        w(f"model {result.model}: cost {args.cost} = {num(result.cost, 6)}, nfev {result.nfev}, "
          f"success {result.success}\n")
        for k, v in result.params.items():
            se = result.stderr.get(k)
            unit = model.spec(k).unit
            if k in result.fixed:
                value = f"{num(v, 6)} {unit} fixed"
            elif se is not None and math.isfinite(se):
                value = f"{num(v, 6)} ± {num(se, 2)} {unit}"
            else:
                value = f"{num(v, 6)} {unit} (no standard error)"
            if (result.band_method or {}).get(k) == "profile" and result.bands is not None:
                lo, hi = result.bands[k]
                value += f" (3-sigma band {num(lo)} .. {num(hi)} {unit}, profile likelihood)"
            w(f"  {k:>6} = {value}\n")
        for c, v in result.rms_residual.items():
            w(f"  rms residual {c}: {num(v, 3, model.column_units(c)[0] if model.column_units(c) else '')}\n")
        for msg in result.warnings:
            w(f"warning: {msg}\n")
    for msg in result.warnings if args.json else []:
        sys.stderr.write(f"warning: {msg}\n")
    return 0
