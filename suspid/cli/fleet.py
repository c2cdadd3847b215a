"""``suspid fleet``: identify every drive log of a fleet on Dask; history, trends, forecasts."""
from __future__ import annotations

import argparse
import math
import sys
from datetime import datetime, timezone
from statistics import NormalDist
from typing import TYPE_CHECKING, Any

from suspid.cli._args import add_fit_options, add_road_option
from suspid.cli._can import add_can_arguments, can_inputs, command_config
from suspid.cli._common import (add_model_option, add_param_options, assignment_warnings,
                                parse_assignments, print_json)
from suspid.cli._lazy import lazy_names
from suspid.cli.identify import parse_x0
from suspid.errors import UsageError
from suspid.models import get_model

if TYPE_CHECKING:
    from estimator.fleet.runner import (AlertConfig, FleetConfig, IdentifySettings, ProgressBar,
                                        available_cpus, run_fleet)
else:
    (AlertConfig, FleetConfig, IdentifySettings, ProgressBar, available_cpus,
     run_fleet) = lazy_names("estimator.fleet.runner", "AlertConfig", "FleetConfig", "IdentifySettings",
                             "ProgressBar", "available_cpus", "run_fleet")


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("fleet", help="identify every drive log of a fleet; trends and forecasts",
                       description="Identify every drive log found (a folder per vehicle; CAN "
                                   "logs or measurement CSVs) exactly as `suspid identify` "
                                   "would, on Dask; keep the history in an SQLite file; per "
                                   "vehicle, robust trends of the free parameters, alerts and "
                                   "limit-crossing forecasts; an HTML report. See docs/fleet.md.")
    add_model_option(p, required=False)
    p.add_argument("--input", nargs="+", action="extend", default=[], metavar="DIR_OR_GLOB",
                   help="folders (searched recursively), glob patterns or log files; the "
                        "vehicle is the folder holding each log (quote patterns)")
    p.add_argument("--dbc", metavar="PATH", default=None,
                   help="DBC for CAN-log input (default: the bundled dbc/suspension.dbc)")
    add_can_arguments(p, "fleet")
    add_param_options(p)
    i = p.add_argument_group("identification (as suspid identify)")
    add_fit_options(
        p, restarts=6, group=i,
        cost="sse (seed cost 1, default) or frobenius (seed cost 2)",
        maxfev="evaluation budget of each fit over all its restarts, further starts and polish "
               "(default: 1200 per free parameter shared by every fit of a drive), as for identify; "
               "restarts, further starts, polish, the data-driven start and the initial state "
               "are the --config file's [fit] table",
        offset="a constant offset in a drive's road column(s) or one position channel "
               "(a sensor zero not at rest), as identify finds it: remove: subtract "
               "it before the drive's fit (default); keep: fit the drive as it is; "
               "either way the drive's first warning and its offset field name it")
    add_road_option(i)
    a = p.add_argument_group("alerts and forecasts")
    a.add_argument("--nominal", action="append", default=[], metavar="NAME=VALUE",
                   help="nominal value of a monitored (free) parameter (SI; default the "
                        "model's documented default, or the last run's in --db)")
    a.add_argument("--alert-drop", type=float, default=0.3, metavar="FRACTION",
                   help="limit (1 - FRACTION) x nominal (default 0.3); the confidence, the "
                        "drives a drop must hold in and the forecast horizon are the --config "
                        "file's [alert] table")
    r = p.add_argument_group("execution, history, report")
    r.add_argument("--scheduler", metavar="tcp://HOST:PORT", default=None,
                   help="run on this existing Dask cluster (the workers must read the logs at "
                        "the same paths); default: a local cluster")
    r.add_argument("--workers", type=int, default=None, metavar="N",
                   help="local Dask worker processes (default and at most: the CPUs available; 0: "
                        "no cluster, in this process)")
    r.add_argument("--db", metavar="PATH", default=None,
                   help="SQLite history of the drives, appended across runs (a log seen "
                        "again is one drive); without --input, report from it alone")
    r.add_argument("--report", metavar="DIR", default=None,
                   help="write DIR/index.html: vehicles by risk, trend plots, failed logs")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    return p


def run(args: argparse.Namespace) -> int:
    settings = None
    cfg = command_config(args, "fleet")
    if args.input:
        if args.model is None:
            raise UsageError("--input needs --model (quarter1, quarter2, half4, ...)")
        model = get_model(args.model)
        x0 = parse_x0(args.x0, model.n_states)
        dbc, smap = can_inputs(args, cfg)
        settings = IdentifySettings(
            model=model.name, fix=parse_assignments(args.fix, "--fix"),
            init=parse_assignments(args.init, "--init"), cost=args.cost,
            x0=x0 if isinstance(x0, str) else tuple(float(v) for v in x0),
            restarts=args.restarts, maxfev=args.maxfev, multistart=args.multistart,
            polish=args.polish, data_start=args.data_start, dbc=str(dbc) if dbc is not None else None, signal_map=smap,
            can_channel=args.can_channel, offset=args.offset,
            j1939_source=args.j1939_source, road=args.road)
    elif args.db is None:
        raise UsageError("give --input DIR_OR_GLOB... with --model, or --db PATH to report from "
                         "the history")
    if not 0 < args.alert_drop < 1:
        raise UsageError(f"--alert-drop: expected a fraction in (0, 1), got {args.alert_drop}")
    nominal = parse_assignments(args.nominal, "--nominal")
    if args.model is not None:
        for k in nominal:
            get_model(args.model).spec(k)
        for msg in assignment_warnings(args, get_model(args.model)):
            sys.stderr.write(f"warning: {msg}\n")
    if args.workers is not None and args.scheduler is None and args.workers > available_cpus():
        sys.stderr.write(f"warning: --workers {args.workers}: {available_cpus()} CPU(s) available; "
                         f"using {available_cpus()} worker processes (each drive is "
                         "single-threaded: more would only share the cores)\n")
    rule = AlertConfig.per_drive(nominal=nominal, drop=args.alert_drop,
                                 z=float(NormalDist().inv_cdf(cfg.get("alert", "confidence", 0.99))),
                                 min_count=cfg.get("alert", "drives", 1),
                                 horizon_days=cfg.get("alert", "horizon_days", 365.0))
    result = run_fleet(FleetConfig(inputs=list(args.input), settings=settings, rule=rule,
                                   scheduler=args.scheduler, workers=args.workers, db=args.db,
                                   report=args.report,
                                   progress=(ProgressBar(sys.stderr)
                                             if cfg.get("fleet", "progress", True) else None)))
    out = result.to_json()
    if args.json:
        print_json(out)
        for msg in _warnings(out):
            sys.stderr.write(f"warning: {msg}\n")
        return 0
    _print_table(out)
    return 0


def _warnings(out: dict[str, Any]) -> list[str]:
    """The vehicles' warnings, then each drive's offset warning prefixed by its path."""
    msgs = [msg for v in out["vehicles"] for msg in v.get("warnings", [])]
    msgs += [f"{d['path']}: {msg}" for d in out["drives"] if d.get("offset")
             for msg in d.get("warnings", []) if msg.startswith("offset:")]
    return msgs


def _date(t: Any) -> str:
    if t is None or not math.isfinite(t):
        return "-"
    return datetime.fromtimestamp(t, tz=timezone.utc).strftime("%Y-%m-%d")


def _days(fc: dict[str, Any]) -> str:
    """``; in 41 d, 33 to 52 d`` after the latest drive ('' when unknown)."""
    d = [fc.get(k) for k in ("days", "days_low", "days_high")]
    if any(x is None for x in d):
        return ""
    return f"; in {d[0]:.0f} d, {d[1]:.0f} to {d[2]:.0f} d"


def _km(fc: dict[str, Any]) -> str:
    """``; at 84200 km, 79900 to 90100 km``, or ``; no distance signal``."""
    if "crossing_km" not in fc:
        return "; no distance signal"
    if fc["crossing_km"] is None:
        return "; no crossing against distance"
    return (f"; at {fc['crossing_km']:,.0f} km, {fc['crossing_km_low']:,.0f} to "
            f"{fc['crossing_km_high']:,.0f} km")


def _print_table(out: dict[str, Any]) -> None:
    w = sys.stdout.write
    ok = sum(1 for d in out["drives"] if d["status"] == "ok")
    w(f"{len(out['vehicles'])} vehicles, {ok} drives identified, {out['unidentified']} not "
      f"identified, {out['failed']} failed ({out['new']} new, {out['reused']} from the "
      f"history) in {out['seconds']:.1f} s\n")
    w(f"{'rank':>4}  {'vehicle':<16} {'risk':<9} {'drives':>6}  alerts / forecasts\n")
    for v in out["vehicles"]:
        notes = [f"ALERT {k}" for k in v["alerts"]]
        notes += [f"{k} reaches {f['limit']:.4g} on {_date(f['crossing_t'])} "
                  f"({_date(f['crossing_t_low'])} to {_date(f['crossing_t_high'])}"
                  f"{_days(f)}{_km(f)})" for k, f in v["forecast"].items()]
        if v.get("unidentified"):
            notes.append(f"{len(v['unidentified'])} drive(s) not identified")
        w(f"{v['rank']:>4}  {v['vehicle']:<16} {v['risk']:<9} {v['drives']:>6}  "
          f"{'; '.join(notes)}\n")
    for msg in _warnings(out):
        w(f"warning: {msg}\n")
    for d in out["drives"]:
        if d["status"] != "ok":
            w(f"{d['status']}: {d['error']}\n")
    if out.get("report"):
        w(f"report: {out['report']}\n")
