"""``suspid monitor``: sliding-window identification (or the EKF) on a CAN stream, with alerts.

Input is a CAN log replayed as fast as possible (``--input LOG``), a measurement CSV
(``--input CSV``, same windows), or a live python-can bus (``--interface I --channel C``).
Output is JSON lines (``--jsonl``): one ``estimate`` (or ``skip``, with the reason) per
window, an ``alert`` (and later a ``clear``) per confident drop, and a closing ``summary``.
See ``docs/monitoring.md``.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any, Callable

from suspid.cli._common import CAN_LOG_SUFFIXES, add_model_option, parse_assignments, print_json
from suspid.can.options import add_can_arguments
from suspid.errors import InputError, UsageError, require_file


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
    p.add_argument("--alert-drop", type=float, default=0.3, metavar="FRACTION",
                   help="alert when a parameter is confidently below (1 - FRACTION) x nominal "
                        "(default 0.3)")
    p.add_argument("--baseline", choices=["ekf"], default=None,
                   help="run the filterpy EKF joint state/parameter estimator instead of the "
                        "sliding-window Nelder-Mead identification")
    p.add_argument("--jsonl", action="store_true",
                   help="print JSON lines (one object per line); without it, one readable line "
                        "per window")
    w = p.add_argument_group("windows (defaults from the model's modes; docs/monitoring.md)")
    w.add_argument("--window", type=float, default=None, metavar="S", help="window length (s)")
    w.add_argument("--step", type=float, default=None, metavar="S", help="window step (s)")
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
    e = p.add_argument_group("EKF baseline")
    e.add_argument("--ekf-params", default="c1,k1", metavar="LIST",
                   help="parameters in the EKF's augmented state (default c1,k1; c1,k1,c2,k2)")
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


def _emitter(jsonl: bool) -> Callable[[dict[str, Any]], None]:
    """JSON lines, or one readable line per event."""
    if jsonl:
        return print_json

    def human(d: dict[str, Any]) -> None:
        typ = d.get("type")
        if typ == "estimate":
            pv = ", ".join(f"{k}={v:.5g}" + (f"±{d['stderr'][k]:.2g}" if k in d.get("stderr", {})
                                              and d["stderr"][k] is not None else "")
                           for k, v in d.get("params", {}).items() if k in d.get("stderr", {}))
            ins = d.get("inspection") or {}
            extra = (f" EUSAMA {ins['eusama_pct']:.0f}% phi_min {ins['phi_min_deg']:.0f}deg"
                     if ins else "")
            if "f_hz" in d:
                pv = f"f={d['f_hz']:.3g} Hz zeta={d['zeta']:.3g}"
            sys.stdout.write(f"t={d['t']:.2f}s {pv}{extra}\n")
        elif typ == "skip":
            sys.stdout.write(f"t={d['t']:.2f}s skipped: {d['reason']}\n")
        elif typ in ("alert", "clear"):
            sys.stdout.write(f"t={d['t']:.2f}s {typ.upper()}: {d['message']}\n")
        else:
            sys.stdout.write(" ".join(f"{k}={v}" for k, v in d.items()) + "\n")
        sys.stdout.flush()

    return human


class _Lazy:
    """Builds the estimator on the first window (channels and sample rate known then)."""

    def __init__(self, factory: Callable[[list[str], float], Any], name: str) -> None:
        self.factory = factory
        self.inner: Any = None
        self.name = name

    def process(self, t: Any, data: Any) -> Any:
        """Build the estimator from the first window, then delegate."""
        if self.inner is None:
            import numpy as np

            present = [c for c, v in data.items() if np.mean(np.isfinite(v)) > 0.5]
            dt = float(np.median(np.diff(t)))
            self.inner = self.factory(present, 1.0 / dt if dt > 0 else 0.0)
        return self.inner.process(t, data)

    def summary(self) -> dict[str, Any]:
        return self.inner.summary() if self.inner is not None else {}


def _open_bus(interface: str, channel: str | None, bitrate: int | None, what: str) -> Any:
    """The bus through the node's and the estimator's one opener (:func:`suspid.can.bus.open_bus`:
    chunked SLCAN reads, data timestamps on ``virtual``, ``udp_multicast`` refused)."""
    from suspid.can.bus import open_bus

    if channel is None:
        raise UsageError(f"{what}: --channel is required with --interface {interface}")
    if interface == "slcan" and str(channel).lower() in ("pty", "pty:"):
        raise UsageError(f"{what}: --channel pty creates a node-side adapter (suspid node); give "
                         "the monitor the /dev/pts/N path the node printed")
    kw: dict[str, Any] = {"bitrate": bitrate} if bitrate else {}
    try:
        return open_bus(interface, channel, **kw)
    except UsageError as exc:
        raise UsageError(f"{what}: {exc}") from None


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
    sys.modules["asammdf"] = None  # type: ignore[assignment]


def run(args: argparse.Namespace) -> int:
    _skip_mf4_backend(args)
    from estimator.alerts import AlertConfig, AlertEngine, AlertStore, CallbackSink
    from estimator.identify import Parameters
    from estimator.stream.config import default_config, default_decimation
    from estimator.stream.monitor import NMWindowEstimator, StreamMonitor
    from suspid.models import get_model

    model = get_model(args.model)
    if args.interface is not None and args.channel is None:
        raise UsageError("--interface needs --channel (e.g. --interface virtual --channel vcan0)")
    emit = _emitter(args.jsonl)
    if args.output_only:
        from estimator.output_only import run_output_only_cli

        return run_output_only_cli(args, model, emit)
    fix = parse_assignments(args.fix, "--fix")
    nominal_in = parse_assignments(args.nominal, "--nominal")
    for k in list(fix) + list(nominal_in):
        model.spec(k)
    both = set(fix) & set(nominal_in)
    if both:
        raise UsageError(f"parameter(s) {', '.join(sorted(both))} given both --fix and --nominal; "
                         "a fixed parameter is not monitored")
    params = Parameters.for_model(model, fix=fix, init=nominal_in)
    if model.scale_invariant and set(model.scale_invariant) <= set(params.free):
        m0 = next(p.name for p in model.params if p.kind in ("mass", "inertia"))
        params[m0].vary = False
        sys.stderr.write(f"warning: every mass, damper and spring is free, so only their ratios "
                         f"are identifiable; holding {m0} at {params[m0].value:g} "
                         f"{model.spec(m0).unit} (give --fix {m0}=VALUE)\n")
    if not params.free:
        raise UsageError("every parameter is fixed (--fix); nothing to monitor")
    values = params.valuesdict()
    nominal = {k: values[k] for k in params.free}
    if not 0 < args.alert_drop < 1:
        raise UsageError(f"--alert-drop: expected a fraction in (0, 1), got {args.alert_drop}")
    cfg = default_config(model, values, 0.0, len(params.free))
    if args.window is not None:
        cfg.window_s = args.window
        if args.step is None:
            cfg.step_s = max(0.05, round(args.window / 2.0, 2))
    if args.step is not None:
        cfg.step_s = args.step
    for opt, attr in (("budget", "maxfev"), ("first_budget", "first_maxfev"),
                      ("sigma_floor", "sigma_floor"), ("min_deflection", "min_deflection")):
        v = getattr(args, opt)
        if v is not None:
            setattr(cfg, attr, v)
    if args.decimate is not None:
        cfg.decimate = args.decimate
    cfg.validate()
    if not 0.5 < args.confidence < 1:
        raise UsageError(f"--confidence: expected a probability in (0.5, 1), got {args.confidence}")
    from statistics import NormalDist

    acfg = AlertConfig(nominal=nominal, drop=args.alert_drop,
                       z=float(NormalDist().inv_cdf(args.confidence)),
                       persistence_s=cfg.step_s if args.persistence is None else args.persistence,
                       hysteresis=args.hysteresis)
    acfg.validate()

    is_ekf = args.baseline == "ekf"
    ekf_aug: list[str] = []
    if is_ekf:
        ekf_aug = [s.strip() for s in args.ekf_params.split(",") if s.strip()]
        for k in ekf_aug:
            model.spec(k)
        acfg.nominal = {k: v for k, v in nominal.items() if k in ekf_aug}
        if not acfg.nominal:
            raise UsageError(f"--ekf-params {args.ekf_params}: none of them is a free parameter")

    def make_nm(channels: list[str], fs: float) -> Any:
        if args.decimate is None:
            cfg.decimate = default_decimation(model, values, fs)
        meas = [c for c in channels if c in model.channels]
        roads = [r for r in model.roads if r in channels]
        if len(roads) < len(model.roads):
            raise InputError(f"the stream carries no road input {', '.join(model.roads)} "
                             f"(channels: {', '.join(channels) or 'none'}); input-output "
                             "identification needs it -- use --output-only for a body "
                             "accelerometer alone")
        return NMWindowEstimator(model, params, cfg, meas, inspection=not args.no_inspection)

    def make_ekf(channels: list[str], fs: float) -> Any:
        from estimator.ekf import EKFTuning, EKFWindowEstimator

        if not all(r in channels for r in model.roads):
            raise InputError(f"the stream carries no road input {', '.join(model.roads)}; the EKF "
                             "needs it -- use --output-only for a body accelerometer alone")
        tun = EKFTuning()
        if args.ekf_q is not None:
            tun.q_param = args.ekf_q
        dec = args.ekf_decimate or max(1, int(math.floor(fs / 250.0 + 1e-9)))
        meas = [c for c in channels if c in model.channels]
        return EKFWindowEstimator(model, values, ekf_aug, meas, tun, decimate=dec)

    estimator = _Lazy(make_ekf if is_ekf else make_nm, "ekf" if is_ekf else "nm")
    store = AlertStore(args.alert_file) if args.alert_file else None
    sinks: list[Any] = [CallbackSink(emit)]
    engine = AlertEngine(acfg, model.name, units={k: model.spec(k).unit for k in nominal},
                         store=store, sinks=sinks)
    mon = StreamMonitor(estimator, emit, engine)
    try:
        extra = run_source(args, model, cfg, mon, sinks)
    finally:
        if store is not None:
            store.close()
    if not args.no_summary:
        if store is not None:
            extra["alert_file"] = str(store.path)
        emit(mon.summary(extra))
    return 0


def run_source(args: argparse.Namespace, model: Any, cfg: Any, mon: Any,
               sinks: list[Any]) -> dict[str, Any]:
    """Stream ``--input`` (CAN log or CSV) or the live bus through ``mon``; shut buses down.

    Returns the source's summary fields (frames, timing) for the final ``summary`` line.
    """
    buses: list[Any] = []
    try:
        if args.input is not None:
            path = require_file(args.input)
            if path.suffix.lower() in CAN_LOG_SUFFIXES:
                return _run_log(args, model, cfg, mon, sinks, buses)
            return _run_csv(args, model, cfg, mon)
        return _run_live(args, model, cfg, mon, sinks, buses)
    finally:
        for b in buses:
            try:
                b.shutdown()
            except Exception:  # pragma: no cover - best effort on the way out
                pass


def _listener(args: argparse.Namespace, model: Any, cfg: Any, time_source: str) -> Any:
    """The CAN layer's DecodeListener with a bounded buffer sized for the windows."""
    from estimator.decode import DecodeListener
    from suspid.can.options import can_inputs

    dbc_path, smap = can_inputs(args)
    if args.dbc:
        dbc_path = Path(args.dbc)
    # rows per message: window + step at up to 2 kHz, power of two
    rows = 1 << max(12, math.ceil(math.log2(max(2.0, (cfg.window_s + 2 * cfg.step_s) * 2000.0))))
    return DecodeListener(model, dbc_path, smap, capacity=rows, growable=False,
                          time_source=time_source)


def _alert_bus(args: argparse.Namespace, sinks: list[Any], listener: Any, buses: list[Any],
               live_bus: Any = None) -> None:
    """Add the SUSPID_Alert frame sink (live bus, or --alert-interface for a replay)."""
    from estimator.alerts import BusAlertSink

    if args.no_alert_frames:
        return
    bus = None
    if args.alert_interface:
        bus = _open_bus(args.alert_interface, args.alert_channel, args.bitrate, "--alert-interface")
        buses.append(bus)
    elif live_bus is not None:
        bus = live_bus
    if bus is not None:
        sinks.append(BusAlertSink(bus, listener.db))


def _run_log(args: argparse.Namespace, model: Any, cfg: Any, mon: Any, sinks: list[Any],
             buses: list[Any]) -> dict[str, Any]:
    """Replay a CAN log as fast as possible through the decoder and the windows."""
    from estimator.stream.drivers import CanWindowDriver, replay_log
    from suspid.can.logs import ReadStats

    listener = _listener(args, model, cfg, args.time_source or "timestamp")
    _alert_bus(args, sinks, listener, buses)
    drv = CanWindowDriver(listener, cfg.window_s, cfg.step_s, mon.window)
    stats = ReadStats()
    replay_log(drv, args.input, stats)
    listener.count_malformed(stats.malformed)
    if drv.windows == 0:
        raise InputError(f"{args.input}: {drv.frames} frames but less data than one window "
                         f"({cfg.window_s:g} s); give a shorter --window")
    out: dict[str, Any] = {"frames": listener.frame_stats(), "windows_cut": drv.windows}
    if stats.truncated:
        out["warnings"] = [f"{args.input}: the file ends inside a record (truncated)"]
    return out


def _run_csv(args: argparse.Namespace, model: Any, cfg: Any, mon: Any) -> dict[str, Any]:
    """Stream a measurement CSV through the same windows."""
    import numpy as np

    from estimator.stream.drivers import run_arrays
    from suspid.io.csvio import read_measurement

    meas = read_measurement(args.input, model)
    data = dict(meas.measured)
    data.update(meas.road)
    if meas.t.size < 3 or meas.t[-1] - meas.t[0] < cfg.window_s:
        raise InputError(f"{args.input}: {meas.t[-1] - meas.t[0]:.3g} s of data, less than one "
                         f"window ({cfg.window_s:g} s); give a shorter --window")
    n = run_arrays(np.asarray(meas.t), data, cfg.window_s, cfg.step_s, mon.window)
    return {"windows_cut": n, "warnings": list(meas.warnings)}


def _run_live(args: argparse.Namespace, model: Any, cfg: Any, mon: Any, sinks: list[Any],
              buses: list[Any]) -> dict[str, Any]:
    """Receive from a live python-can bus until idle, --duration, SIGINT or SIGTERM."""
    from estimator.stream.drivers import CanWindowDriver, LiveStop, run_bus

    bus = _open_bus(args.interface, args.channel, args.bitrate, "--interface")
    buses.append(bus)
    listener = _listener(args, model, cfg, args.time_source or "tick")
    _alert_bus(args, sinks, listener, buses, live_bus=bus)
    drv = CanWindowDriver(listener, cfg.window_s, cfg.step_s, mon.window)
    stop = LiveStop(duration=args.duration,
                    idle_timeout=None if not args.idle_timeout else args.idle_timeout)
    stop.install()
    try:
        n = run_bus(drv, bus, stop)
    finally:
        stop.restore()
    return {"frames": listener.frame_stats(), "frames_received": n, "windows_cut": drv.windows,
            "stopped": stop.reason}
