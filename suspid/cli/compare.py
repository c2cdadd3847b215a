"""``suspid compare``: sliding-window Nelder-Mead vs the EKF baseline on the same stream (a log
or CSV, or the synthetic damper-wear stream): accuracy, convergence, alert delay, CPU time.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from suspid.cli._args import add_road_option, options_from_config
from suspid.cli._can import add_can_arguments, can_inputs, command_config
from suspid.cli._common import add_model_option, parse_assignments, print_json
from suspid.cli._lazy import lazy_names
from suspid.errors import UsageError
from suspid.models import get_model

if TYPE_CHECKING:
    from estimator.stream.compare import compare, load_stream, plot
    from estimator.stream.wear_streams import damper_wear, production_wear
else:
    compare, load_stream, plot = lazy_names("estimator.stream.compare", "compare", "load_stream",
                                            "plot")
    damper_wear, production_wear = lazy_names("estimator.stream.wear_streams", "damper_wear",
                                              "production_wear")


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("compare", help="compare the NM window identifier with the EKF on one stream",
                       description="Run the sliding-window Nelder-Mead identifier and the filterpy "
                                   "EKF on the same stream; report parameter RMSE against the "
                                   "truth, convergence time, alert delay, false alarms and CPU "
                                   "time per sample, and plot the tracks.")
    add_model_option(p)
    src = p.add_mutually_exclusive_group()
    src.add_argument("--input", metavar="PATH", help="CAN log or measurement CSV")
    src.add_argument("--scenario", choices=["damper-wear"], default=None,
                     help="synthetic stream with known truth (default when --input is absent)")
    p.add_argument("--dbc", metavar="PATH", default=None, help="DBC for a CAN log")
    add_can_arguments(p, "compare")
    p.add_argument("--truth", metavar="CSV", default=None,
                   help="true parameter values over time for --input: columns t and parameter names")
    p.add_argument("--duration", type=float, default=150.0, help="scenario length (s), default 150")
    p.add_argument("--fs", type=float, default=500.0, help="scenario sample rate (Hz), default 500")
    p.add_argument("--seed", type=int, default=0, help="scenario road seed")
    p.add_argument("--wear-to", type=float, default=0.5,
                   help="scenario: c1 at the end as a fraction of nominal (default 0.5)")
    p.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE",
                   help="known parameter (SI); repeatable (default for the scenario: m1, m2, c2, k2 "
                        "at their true values)")
    p.add_argument("--nominal", action="append", default=[], metavar="NAME=VALUE",
                   help="nominal value of a monitored parameter (SI)")
    p.add_argument("--init", action="append", default=[], metavar="NAME=VALUE",
                   help="starting value of a free parameter for both estimators (SI; default its "
                        "nominal value) -- shows the convergence time")
    p.add_argument("--alert-drop", type=float, default=0.3, metavar="FRACTION",
                   help="both estimators alert when a parameter is confidently below "
                        "(1 - FRACTION) x nominal (default 0.3, as monitor)")
    p.add_argument("--window", type=float, default=None, metavar="S",
                   help="window length of both estimators (s; default from the model's modes, "
                        "as monitor)")
    p.add_argument("--step", type=float, default=None, metavar="S",
                   help="window step of both (s; default half the window, as monitor)")
    add_road_option(p)
    p.add_argument("--plot", metavar="PNG", default=None,
                   help="write the comparison plot here: one panel per monitored parameter")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    return p


#: rows of the text table: metric key and its label
TABLE_ROWS = (("rmse_pct", "RMS error vs truth (%)"), ("error_over_stderr_rms", "error / stderr (RMS)"),
              ("convergence_s", "convergence (s)"), ("alert_delay_s", "alert after crossing (s)"),
              ("false_alarms", "false alarms"), ("forecast_lead_s", "first forecast lead (s)"),
              ("forecast_first_contains", "its interval holds the crossing"))


def comparison_table(out: dict[str, Any]) -> str:
    """The report as a text table: the sliding window and the EKF side by side."""
    nm, ekf = out["nm"], out["ekf_result"]

    def cell(v: Any) -> str:
        if v is None:
            return "-"
        return f"{v:.3g}" if isinstance(v, float) else str(v)

    lines = [f"model {out['model']}, road {out['road']}: sliding window vs EKF",
             f"{'':38} {'window':>12} {'EKF':>12}",
             f"{'estimates':38} {nm['estimates']:>12} {ekf['estimates']:>12}",
             f"{'CPU per sample (us)':38} {nm['cpu_us_per_sample']:>12.3g} "
             f"{ekf['cpu_us_per_sample']:>12.3g}"]
    for k in nm["params"]:
        a, b = nm["params"][k], ekf["params"].get(k, {})
        for key, label in TABLE_ROWS:
            if key in a or key in b:
                lines.append(f"{k + ': ' + label:38} {cell(a.get(key)):>12} {cell(b.get(key)):>12}")
    if ekf.get("held"):
        lines += [f"EKF holds {k}: {why}" for k, why in ekf["held"].items()]
    return "\n".join(lines) + "\n"


def run(args: argparse.Namespace) -> int:
    cfg = command_config(args, "compare")
    model = get_model(args.model)
    fix = parse_assignments(args.fix, "--fix")
    nominal = parse_assignments(args.nominal, "--nominal")
    init = parse_assignments(args.init, "--init")
    if args.input is None:
        if not 0 < args.wear_to <= 1:
            raise UsageError(f"--wear-to: expected a fraction in (0, 1], got {args.wear_to}")
        if args.duration < 30 or args.fs < 50:
            raise UsageError(f"--duration >= 30 s and --fs >= 50 Hz needed, got {args.duration}, "
                             f"{args.fs}")
        # with the road unknown: what a production car sends (no road)
        make = production_wear if args.road == "unknown" else damper_wear
        s = make(model, duration=args.duration, fs=args.fs, seed=args.seed,
                 c_end_fraction=args.wear_to)
        t, data = s.t, s.data
        truth: dict[str, Any] | None = dict(s.truth)
        base = dict(s.nominal)
        if not fix:
            fix = {k: base[k] for k in ("m1", "m2", "c2", "k2") if k in base}
        nominal = {k: nominal.get(k, base[k]) for k in model.param_names
                   if k not in fix and k in base}
        source = f"scenario damper-wear (seed {args.seed})"
    else:
        dbc, smap = can_inputs(args, cfg)
        t, data, truth = load_stream(model, args.input, Path(args.dbc) if args.dbc else dbc,
                                     smap, args.truth, channel=args.can_channel,
                                     j1939_source=args.j1939_source)
        source = args.input
    window, alert, ekf = options_from_config(args, cfg)
    out, recs = compare(model, t, data, truth, fix=fix, nominal=nominal, init=init,
                        window=window, alert=alert, ekf=ekf, source=source, road=args.road)
    if args.plot:
        plot(args.plot, t, truth, recs, out["nominal"], args.alert_drop)
        out["plot"] = args.plot
    for w in out.get("warnings", []):
        sys.stderr.write(f"warning: {w}\n")
    if args.json:
        print_json(out)
    else:
        sys.stdout.write(comparison_table(out))
    return 0
