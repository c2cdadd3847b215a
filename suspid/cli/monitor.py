"""``suspid monitor``: sliding-window identification (or the EKF) on a CAN stream, with alerts
(``docs/monitoring.md``)."""
from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from suspid.cli._args import add_road_option, options_from_config
from suspid.cli._can import add_can_arguments, can_inputs, command_config
from suspid.cli._common import add_model_option, assignment_warnings, parse_assignments, print_json
from suspid.cli._format import data_time, num, summary_lines
from suspid.cli._lazy import lazy_names
from suspid.errors import UsageError
from suspid.models import get_model
from suspid.models.base import SuspensionModel

if TYPE_CHECKING:
    from estimator.stream.config import OutputOnlyOptions
else:
    # resolved in run(), after _skip_mf4_backend (the estimator loads python-can)
    OutputOnlyOptions, = lazy_names("estimator.stream.config", "OutputOnlyOptions")


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "monitor", help="watch a suspension on a CAN stream and alert on worn parts",
        description="Stream CAN frames (a log replayed as fast as possible, or a live "
                    "python-can bus) through the rolling buffer and the sliding-window "
                    "identification; print one JSON line per window and an alert when a "
                    "parameter has confidently dropped below (1 - FRACTION) x nominal. "
                    "Window, alert, EKF, receiver and output-only tuning: the --config file "
                    "(docs/configuration.md).")
    add_model_option(p)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--input", metavar="LOG",
                     help="CAN log (.log candump -L, .asc, .blf, .trc, .mf4) replayed as fast as "
                          "possible; a measurement CSV is accepted too")
    src.add_argument("--interface", metavar="I",
                     help="live python-can interface (virtual, slcan, socketcan, ...)")
    p.add_argument("--channel", metavar="C",
                   help="channel of --interface (e.g. a virtual channel name, /dev/pts/N, can0)")
    p.add_argument("--dbc", metavar="PATH", default=None,
                   help="DBC of the CAN data (default: suspid's dbc/suspension.dbc)")
    add_can_arguments(p, "monitor")
    p.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE",
                   help="hold a parameter at a known value (SI), e.g. --fix m1=300; repeatable")
    p.add_argument("--nominal", action="append", default=[], metavar="NAME=VALUE",
                   help="nominal value of a monitored parameter (SI; default the model's "
                        "documented default); also the first window's starting value")
    p.add_argument("--init", action="append", default=[], metavar="NAME=VALUE",
                   help="starting value of a free parameter when it differs from nominal (SI), "
                        "for the sliding window and the EKF alike")
    p.add_argument("--alert-drop", type=float, default=0.3, metavar="FRACTION",
                   help="alert when a parameter is confidently below (1 - FRACTION) x nominal "
                        "(default 0.3)")
    p.add_argument("--baseline", choices=["ekf"], default=None,
                   help="run the filterpy EKF joint state/parameter estimator instead of the "
                        "sliding-window Nelder-Mead identification")
    p.add_argument("--jsonl", action="store_true",
                   help="print JSON lines (one object per line); without it, one readable line "
                        "per window")
    add_road_option(p)
    p.add_argument("--window", type=float, default=None, metavar="S",
                   help="window length (s; default from the model's modes, docs/monitoring.md); "
                        "a window and two steps span at most 1000 s")
    p.add_argument("--step", type=float, default=None, metavar="S",
                   help="window step (s; default half the window), at most 10 windows")
    p.add_argument("--alert-file", metavar="PATH", default=None,
                   help="durable append-only alert log (JSON lines, fsynced); a restarted "
                        "monitor neither loses nor repeats the alerts in it")
    p.add_argument("--output-only", action="store_true",
                   help="no road/wheel sensor: track the body mode's frequency and damping "
                        "ratio from a body accelerometer per window (60 s every 30 s by "
                        "default)")
    p.add_argument("--no-inspection", action="store_true",
                   help="leave out the virtual EUSAMA / EGEA damper test")
    return p


def _text(d: dict[str, Any], model: SuspensionModel | None = None) -> str:
    """One readable line for an event's JSON form (a few for the summary)."""
    typ = d.get("type")
    when = data_time(float(d["t"])) if "t" in d else ""
    if typ == "estimate":
        se = d.get("stderr", {})
        pv = ", ".join(f"{k} {num(v, 5)}" + (f" ± {num(se[k], 2)}" if se.get(k) is not None else "")
                       + (f" {model.spec(k).unit}" if model is not None and k in model.param_names
                          else "")
                       for k, v in d.get("params", {}).items() if k in se)
        ins = d.get("inspection") or {}
        extra = (f", EUSAMA {ins['eusama_pct']:.0f} %, phi_min {ins['phi_min_deg']:.0f} deg"
                 if ins else "")
        if "f_hz" in d:
            pv = (f"f_body {num(d['f_hz'], 3, 'Hz')}, zeta_body {num(d['zeta'], 3)}"
                  + ("" if se.get("f_body") is not None else " (no standard error)"))
        return f"{when} {pv}{extra}" + (" MISFIT" if d.get("misfit") else "")
    if typ == "skip":
        return f"{when} skipped: {d['reason']}"
    if typ in ("alert", "clear", "forecast", "forecast_withdrawn", "warning"):
        return f"{when} {typ.replace('_', ' ').upper()}: {d['message']}"
    if typ == "summary":
        return "\n".join(summary_lines(d))
    return " ".join(f"{k}={num(v)}" for k, v in d.items() if not isinstance(v, (dict, list)))


def _skip_mf4_backend(args: argparse.Namespace) -> None:
    """Keep python-can from importing asammdf (slow) when the input is not an MF4 log: a
    ``None`` entry in :data:`sys.modules` makes that optional import fail in this process."""
    src = str(getattr(args, "input", "") or "")
    if src.lower().endswith(".mf4") or "can" in sys.modules or "asammdf" in sys.modules:
        return
    sys.modules["asammdf"] = None  # type: ignore[assignment]  # None is the documented "fails" marker


def run(args: argparse.Namespace) -> int:
    _skip_mf4_backend(args)
    # imported here: it loads python-can, which must come after _skip_mf4_backend
    from estimator.stream.pipeline import Source, monitor_spec, run_monitor, warn  # noqa: PLC0415

    cfg = command_config(args, "monitor")
    model = get_model(args.model)
    if args.interface is not None and args.channel is None:
        raise UsageError("--interface needs --channel (e.g. --interface virtual --channel vcan0)")
    baseline = "output_only" if args.output_only else (args.baseline or "nm")
    window, alert, ekf = options_from_config(args, cfg)
    spec = monitor_spec(
        model, fix=parse_assignments(args.fix, "--fix"),
        nominal=parse_assignments(args.nominal, "--nominal"),
        init=parse_assignments(args.init, "--init"), baseline=baseline,
        road=None if args.output_only else args.road, window=window, alert=alert, ekf=ekf,
        output_only=OutputOnlyOptions(**cfg.table("output_only")),
        inspection=not args.no_inspection)
    warn(spec)
    for msg in assignment_warnings(args, model):
        sys.stderr.write(f"warning: {msg}\n")

    def emit(ev: Any) -> None:
        """JSON lines, or one readable line per event; a ``warning`` also on stderr."""
        d = ev.to_json()
        if d.get("type") == "warning":
            sys.stderr.write(f"warning: {data_time(float(d['t']))}: {d['message']}\n")
            sys.stderr.flush()
        if args.jsonl:
            print_json(d)
        else:
            sys.stdout.write(_text(d, model) + "\n")
            sys.stdout.flush()

    dbc_path, smap = can_inputs(args, cfg)
    source = Source(input=args.input, interface=args.interface, channel=args.channel,
                    dbc=dbc_path, signal_map=smap, can_channel=args.can_channel,
                    j1939_source=args.j1939_source,
                    **cfg.fields("live", {"idle_timeout_s": "idle_timeout", "duration_s": "duration"}))
    summary = run_monitor(spec, source, emit, alert_file=args.alert_file)
    if cfg.get("monitor", "summary", True):
        emit(summary)
    return 0
