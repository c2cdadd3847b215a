"""``suspid monitor``: sliding-window identification (or the EKF) on a CAN stream, with alerts.

Input is a CAN log replayed as fast as possible (``--input LOG``), a measurement CSV
(``--input CSV``, same windows), or a live python-can bus (``--interface I --channel C``).
Output is JSON lines (``--jsonl``): one ``estimate`` (or ``skip``, with the reason) per
window, an ``alert`` (and later a ``clear``) per confident drop, and a closing ``summary``.
See ``docs/monitoring.md``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from suspid.can.options import add_can_arguments, add_receive_arguments, can_inputs
from suspid.cli._args import add_offset_option, add_road_option
from suspid.cli._common import add_model_option, assignment_warnings, parse_assignments, print_json
from suspid.cli._format import data_time, num, summary_lines
from suspid.errors import UsageError
from suspid.models import get_model
from suspid.models.base import SuspensionModel

if TYPE_CHECKING:
    from estimator.stream.pipeline import Source

#: the library's default forecast horizon (estimator.alerts.forecast.DEFAULT_HORIZON_S), for
#: the help text only: importing the estimator at the top would load python-can before
#: run()'s MF4-backend skip
HORIZON_HELP_S = 60.0


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "monitor", help="watch a suspension on a CAN stream and alert on worn parts",
        description="Stream CAN frames (a log replayed as fast as possible, or a live "
                    "python-can bus) through the rolling buffer and the sliding-window "
                    "identification; print one JSON line per window and an alert when a "
                    "parameter has confidently dropped below (1 - FRACTION) x nominal.")
    add_model_option(p)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--input", metavar="LOG",
                     help="CAN log (.log candump -L, .asc, .blf, .trc, .mf4) replayed as fast as "
                          "possible; a measurement CSV is accepted too")
    src.add_argument("--interface", metavar="I",
                     help="live python-can interface (virtual, slcan, socketcan, ...)")
    p.add_argument("--channel", metavar="C",
                   help="channel of --interface (e.g. a virtual channel name, /dev/pts/N, can0)")
    p.add_argument("--bitrate", type=int, default=None, help="bitrate for --interface (if needed)")
    p.add_argument("--dbc", metavar="PATH", default=None,
                   help="DBC of the CAN data (default: suspid's dbc/suspension.dbc)")
    add_can_arguments(p)
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
    w = p.add_argument_group("windows (defaults from the model's modes; docs/monitoring.md)")
    w.add_argument("--window", type=float, default=None, metavar="S",
                   help="window length (s); a window and two steps span at most 1000 s")
    w.add_argument("--step", type=float, default=None, metavar="S",
                   help="window step (s), at most 10 windows")
    w.add_argument("--decimate", type=int, default=None, metavar="N",
                   help="fit every N-th sample (default: 20 samples per wheel-hop period)")
    w.add_argument("--budget", type=int, default=None, metavar="N",
                   help="Nelder-Mead evaluations per warm-started window (default 40 per free "
                        "parameter)")
    w.add_argument("--first-budget", type=int, default=None, metavar="N",
                   help="evaluations of the first, cold-started window (default 250 per free "
                        "parameter)")
    w.add_argument("--sigma-floor", type=float, default=None, metavar="REL",
                   help="relative stderr added in quadrature to each window's (default 0.005)")
    w.add_argument("--min-deflection", type=float, default=None, metavar="M",
                   help="skip windows whose RMS suspension deflection is below this (m, "
                        "default 0.0005)")
    w.add_argument("--road-fusion", type=float, default=None, metavar="HZ",
                   help="road displacement fed to each window's fit: measured r below HZ, "
                        "integral of the measured r_dot above (default 1.5 x the highest "
                        "natural frequency; 0: r as measured)")
    w.add_argument("--road-lowpass", type=float, default=None, metavar="HZ",
                   help="zero-phase low-pass of the road displacement fed to each window's "
                        "fit (Hz, -6 dB; default 0: off)")
    w.add_argument("--window-drift", default=None, metavar="NAMES",
                   help="comma-separated free parameters fitted with a linear drift over each "
                        "window, so their estimate refers to the window's end (default: every "
                        "free damper and spring of the struts; 'none': every parameter "
                        "constant over the window; docs/monitoring.md)")
    add_offset_option(w, "a constant offset in the road column(s) or one position channel (a "
                         "sensor zero not at the rest position), looked for on the first fitted "
                         "window: 'remove' (default) subtracts it from every window, 'keep' "
                         "fits the data as they are; either way a warning and the summary's "
                         "offset field name it")
    a = p.add_argument_group("alerts")
    a.add_argument("--alert-file", metavar="PATH", default=None,
                   help="durable append-only alert log (JSON lines, fsynced); a restarted "
                        "monitor neither loses nor repeats the alerts in it")
    a.add_argument("--persistence", type=float, default=None, metavar="S",
                   help="data time the drop must persist before alerting (default one step)")
    a.add_argument("--confidence", type=float, default=0.99, metavar="P",
                   help="one-sided confidence of the bound (default 0.99)")
    a.add_argument("--hysteresis", type=float, default=0.05, metavar="FRACTION",
                   help="clear an alert only above (1 - drop + this) x nominal (default 0.05)")
    a.add_argument("--no-alert-frames", action="store_true",
                   help="do not send SUSPID_Alert frames on the live bus")
    a.add_argument("--alert-interface", metavar="I", default=None,
                   help="send SUSPID_Alert frames on this bus (default: the live bus)")
    a.add_argument("--alert-channel", metavar="C", default=None, help="channel of --alert-interface")
    a.add_argument("--forecast-horizon", type=float, default=None, metavar="SECONDS",
                   help="announce a predicted crossing of (1 - FRACTION) x nominal when it is "
                        f"due within this much data time (default {HORIZON_HELP_S:g} s)")
    e = p.add_argument_group("EKF baseline")
    e.add_argument("--ekf-params", default=None, metavar="LIST",
                   help="parameters in the EKF's augmented state (default: every free damper "
                        "and spring, as the sliding window estimates them)")
    e.add_argument("--ekf-q", type=float, default=None, metavar="Q",
                   help="parameter random walk (relative per sqrt(s), default 0.005)")
    e.add_argument("--ekf-decimate", type=int, default=None, metavar="N",
                   help="run the EKF on every N-th sample (default: 250 Hz or less)")
    l = p.add_argument_group("live bus")
    l.add_argument("--duration", type=float, default=None, metavar="S",
                   help="stop after S seconds of wall time")
    l.add_argument("--idle-timeout", type=float, default=5.0, metavar="S",
                   help="stop when no frame arrived for S seconds (default 5; 0 = never)")
    l.add_argument("--time-source", choices=["timestamp", "tick"], default=None,
                   help="data time from frame timestamps (logs) or SN_Sync ticks (default for "
                        "a live bus)")
    add_receive_arguments(l)
    o = p.add_argument_group("output-only mode (body accelerometer only)")
    o.add_argument("--output-only", action="store_true",
                   help="no road/wheel sensor: track the body mode's frequency and damping "
                        "ratio from a body accelerometer per window")
    o.add_argument("--accel-channel", default=None, metavar="CH",
                   help="channel of the body acceleration (default x1_ddot / x_ddot)")
    o.add_argument("--oo-method", choices=["carma", "ar"], default="carma",
                   help="body-mode estimator: carma (parametric spectral fit, default) or ar "
                        "(AR(6) poles); windows default to 60 s every 30 s")
    p.add_argument("--no-inspection", action="store_true",
                   help="leave out the virtual EUSAMA / EGEA damper test")
    p.add_argument("--no-summary", action="store_true", help="do not print the closing summary line")
    return p


def _text(d: dict[str, Any], model: SuspensionModel | None = None) -> str:
    """One readable line for an event's JSON form (a few lines for the summary); ``model``
    gives the parameters' units."""
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
    if typ in ("alert", "clear"):
        return f"{when} {typ.upper()}: {d['message']}"
    if typ == "forecast":
        return f"{when} FORECAST: {d['message']}"
    if typ == "forecast_withdrawn":
        return f"{when} FORECAST WITHDRAWN: {d['message']}"
    if typ == "warning":
        return f"{when} WARNING: {d['message']}"
    if typ == "summary":
        return "\n".join(summary_lines(d))
    return " ".join(f"{k}={num(v)}" for k, v in d.items() if not isinstance(v, (dict, list)))


def _drift_names(arg: str | None) -> tuple[str, ...] | None:
    """``--window-drift``: ``None`` (the default set), ``()`` for ``none``, else the names."""
    if arg is None:
        return None
    names = tuple(x.strip() for x in arg.split(",") if x.strip())
    return () if names in ((), ("none",)) else names


def _emitter(jsonl: bool, model: SuspensionModel | None = None) -> Callable[[Any], None]:
    """The sink: JSON lines, or one readable line per event; a ``warning`` also on stderr."""
    def emit(ev: Any) -> None:
        d = ev.to_json()
        if d.get("type") == "warning":
            sys.stderr.write(f"warning: {data_time(float(d['t']))}: {d['message']}\n")
            sys.stderr.flush()
        if jsonl:
            print_json(d)
        else:
            sys.stdout.write(_text(d, model) + "\n")
            sys.stdout.flush()

    return emit


def _skip_mf4_backend(args: argparse.Namespace) -> None:
    """Keep python-can from importing asammdf (and with it pandas and sympy, ~1.2 s of CPU at
    every start) when the input is not an MF4 log.

    ``can.io.mf4`` imports asammdf inside ``try/except ImportError`` and is only needed to
    read or write ``.mf4``; a ``None`` entry in :data:`sys.modules` makes that import fail
    fast in this process only. Nothing is changed if python-can or asammdf is loaded already.
    """
    src = str(getattr(args, "input", "") or "")
    if src.lower().endswith(".mf4") or "can" in sys.modules or "asammdf" in sys.modules:
        return
    sys.modules["asammdf"] = None  # type: ignore[assignment]  # None is the documented "fails" marker


def source_from_args(args: argparse.Namespace) -> "Source":
    """The stream options of ``monitor`` as a :class:`~estimator.stream.pipeline.Source`."""
    from estimator.stream.pipeline import Source  # noqa: PLC0415 - see run()

    dbc_path, smap = can_inputs(args)
    if args.dbc:
        dbc_path = Path(args.dbc)
    return Source(input=args.input, interface=args.interface, channel=args.channel,
                  bitrate=args.bitrate, dbc=dbc_path, signal_map=smap,
                  can_channel=args.can_channel, j1939_source=args.j1939_source,
                  time_source=args.time_source, duration=args.duration,
                  idle_timeout=args.idle_timeout, rx_buffer_s=args.rx_buffer,
                  slcan_timestamps=args.slcan_timestamps, alert_frames=not args.no_alert_frames,
                  alert_interface=args.alert_interface, alert_channel=args.alert_channel)


def run(args: argparse.Namespace) -> int:
    _skip_mf4_backend(args)
    # the estimator is imported here, not at the top: it loads python-can, and
    # _skip_mf4_backend must run before that (python-can imports asammdf when it loads)
    from estimator.stream.pipeline import monitor_spec, run_monitor, warn  # noqa: PLC0415

    model = get_model(args.model)
    if args.interface is not None and args.channel is None:
        raise UsageError("--interface needs --channel (e.g. --interface virtual --channel vcan0)")
    baseline = "output_only" if args.output_only else (args.baseline or "nm")
    ekf_params = ([s.strip() for s in args.ekf_params.split(",") if s.strip()]
                  if args.ekf_params else None)
    spec = monitor_spec(
        model, fix=parse_assignments(args.fix, "--fix"),
        nominal=parse_assignments(args.nominal, "--nominal"),
        init=parse_assignments(args.init, "--init"), baseline=baseline,
        alert_drop=args.alert_drop, confidence=args.confidence, persistence=args.persistence,
        hysteresis=args.hysteresis, window=args.window, step=args.step,
        window_overrides={"maxfev": args.budget, "first_maxfev": args.first_budget,
                          "sigma_floor": args.sigma_floor, "min_deflection": args.min_deflection,
                          "road_fusion_hz": args.road_fusion, "road_lowpass_hz": args.road_lowpass,
                          "drift": _drift_names(args.window_drift), "offset": args.offset},
        decimate=args.decimate, inspection=not args.no_inspection,
        forecast_horizon=args.forecast_horizon, ekf_params=ekf_params, ekf_q=args.ekf_q,
        ekf_decimate=args.ekf_decimate, accel_channel=args.accel_channel,
        oo_method=getattr(args, "oo_method", None) or "carma",
        road=None if args.output_only else args.road)
    warn(spec)
    for msg in assignment_warnings(args, model):
        sys.stderr.write(f"warning: {msg}\n")
    emit = _emitter(args.jsonl, model)
    summary = run_monitor(spec, source_from_args(args), emit, alert_file=args.alert_file)
    if not args.no_summary:
        emit(summary)
    return 0
