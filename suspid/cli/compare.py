"""``suspid compare``: sliding-window Nelder-Mead vs the EKF baseline on the same stream.

The stream is a CAN log or measurement CSV (``--input``; truth only with ``--truth``), or
the synthetic damper-wear stream (``--scenario damper-wear``, the default: a quarter car on
an ISO 8608 class C road at 50 km/h whose damper ``c1`` falls linearly from nominal to half
between 20 s and the end). Prints one JSON object (``--json``) with per-method metrics --
parameter RMSE against the truth, convergence time, alert delay, false alarms, CPU
microseconds per sample -- and writes one plot (``--plot PNG``).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from suspid.cli._common import CAN_LOG_SUFFIXES, add_model_option, parse_assignments, print_json
from suspid.can.options import add_can_arguments
from suspid.errors import InputError, UsageError, require_file


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
    add_can_arguments(p)
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
    p.add_argument("--alert-drop", type=float, default=0.3, metavar="FRACTION")
    p.add_argument("--ekf-params", default="c1,k1", metavar="LIST",
                   help="EKF augmented parameters (default c1,k1)")
    p.add_argument("--ekf-q", type=float, default=None, metavar="Q",
                   help="EKF parameter random walk (relative per sqrt(s), default 0.005)")
    p.add_argument("--ekf-decimate", type=int, default=None, metavar="N",
                   help="EKF on every N-th sample (default: 250 Hz or less)")
    p.add_argument("--window", type=float, default=None, metavar="S")
    p.add_argument("--step", type=float, default=None, metavar="S")
    p.add_argument("--param", default="c1", help="parameter to plot (default c1)")
    p.add_argument("--plot", metavar="PNG", default=None, help="write the comparison plot here")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    return p


def _stream(args: argparse.Namespace, model: Any
            ) -> tuple[Any, dict[str, Any], dict[str, Any] | None, dict[str, float]]:
    """``(t, data, truth or None, true/nominal params)``."""
    if args.input is None:
        from estimator.stream.scenarios import damper_wear

        if not 0 < args.wear_to <= 1:
            raise UsageError(f"--wear-to: expected a fraction in (0, 1], got {args.wear_to}")
        if args.duration < 30 or args.fs < 50:
            raise UsageError(f"--duration >= 30 s and --fs >= 50 Hz needed, got {args.duration}, {args.fs}")
        s = damper_wear(model, duration=args.duration, fs=args.fs, seed=args.seed,
                        c_end_fraction=args.wear_to)
        return s.t, s.data, s.truth, dict(s.nominal)
    path = require_file(args.input)
    if path.suffix.lower() in CAN_LOG_SUFFIXES:
        from estimator.decode import load_log_as_measurement
        from suspid.can.options import can_inputs

        dbc, smap = can_inputs(args)
        if args.dbc:
            dbc = Path(args.dbc)
        meas, _ = load_log_as_measurement(path, model, dbc, smap)
    else:
        from suspid.io.csvio import read_measurement

        meas = read_measurement(path, model)
    data = dict(meas.measured)
    data.update(meas.road)
    truth = None
    if args.truth:
        import csv

        try:
            with open(args.truth, newline="") as fh:
                rows = list(csv.DictReader(fh))
        except OSError as exc:
            raise InputError(f"{args.truth}: cannot read: {exc.strerror}") from None
        if not rows or "t" not in rows[0]:
            raise InputError(f"{args.truth}: expected a header with a 't' column")
        try:
            tt = np.array([float(r["t"]) for r in rows])
            truth = {k: np.interp(meas.t, tt, [float(r[k]) for r in rows])
                     for k in rows[0] if k != "t" and k in model.param_names}
        except ValueError as exc:
            raise InputError(f"{args.truth}: non-numeric value ({exc})") from None
    return meas.t, data, truth, model.defaults()


def run(args: argparse.Namespace) -> int:
    from estimator.alerts import AlertConfig
    from estimator.ekf import EKFTuning, EKFWindowEstimator
    from estimator.identify import Parameters
    from estimator.stream.compare import metrics, plot, run_one
    from estimator.stream.config import default_config
    from estimator.stream.monitor import NMWindowEstimator
    from suspid.models import get_model

    model = get_model(args.model)
    if model.name != "quarter2":
        raise UsageError(f"compare runs the quarter-car EKF; --model quarter2 expected, got {model.name}")
    t, data, truth, base = _stream(args, model)
    fix = parse_assignments(args.fix, "--fix")
    if not fix and args.input is None:
        fix = {k: base[k] for k in ("m1", "m2", "c2", "k2")}
    nominal_in = parse_assignments(args.nominal, "--nominal")
    for k in list(fix) + list(nominal_in):
        model.spec(k)
    init = {k: v for k, v in nominal_in.items() if k not in fix}
    if args.input is None:
        init = {k: init.get(k, base[k]) for k in model.param_names if k not in fix}
    params = Parameters.for_model(model, fix=fix, init=init)
    if set(model.scale_invariant) <= set(params.free):
        params["m1"].vary = False
    values = params.valuesdict()
    nominal = {k: values[k] for k in params.free}
    start = parse_assignments(args.init, "--init")
    for k in start:
        model.spec(k)
        if k not in nominal:
            raise UsageError(f"--init {k}: not a free parameter")
        params[k].value = start[k]
    start_values = params.valuesdict()
    fs = 1.0 / float(np.median(np.diff(t)))
    cfg = default_config(model, values, fs, len(params.free))
    if args.window is not None:
        cfg.window_s = args.window
        cfg.step_s = args.step or max(0.05, round(args.window / 2, 2))
    elif args.step is not None:
        cfg.step_s = args.step
    cfg.validate()
    acfg = AlertConfig(nominal, drop=args.alert_drop, persistence_s=cfg.step_s)
    acfg.validate()
    channels = [c for c in model.channels if c in data]
    if not all(r in data for r in model.roads):
        raise InputError("the stream has no road input; compare needs input-output data")
    aug = [s.strip() for s in args.ekf_params.split(",") if s.strip()]
    for k in aug:
        model.spec(k)
    tun = EKFTuning()
    if args.ekf_q is not None:
        tun.q_param = args.ekf_q
    dec = args.ekf_decimate or max(1, int(np.floor(fs / 250.0 + 1e-9)))

    nm = NMWindowEstimator(model, params, cfg, channels, inspection=False)
    rec_nm = run_one(nm, t, data, cfg.window_s, cfg.step_s, acfg, model.name)
    ekf_start = dict(start_values)
    ekf = EKFWindowEstimator(model, ekf_start, aug, channels, tun, decimate=dec)
    ekf_alert = AlertConfig({k: v for k, v in nominal.items() if k in aug}, drop=args.alert_drop,
                            persistence_s=cfg.step_s)
    rec_ekf = run_one(ekf, t, data, cfg.window_s, cfg.step_s, ekf_alert, model.name)
    n = int(t.size)
    out: dict[str, Any] = {
        "model": model.name,
        "stream": {"source": args.input or f"scenario damper-wear (seed {args.seed})",
                   "duration_s": float(t[-1] - t[0]), "fs_hz": fs, "samples": n,
                   "channels": channels},
        "window": {"window_s": cfg.window_s, "step_s": cfg.step_s, "decimate": cfg.decimate,
                   "budget": cfg.maxfev},
        "ekf": {"augmented": aug, "q_param": tun.q_param, "decimate": dec},
        "nominal": nominal, "start": {k: start_values[k] for k in nominal},
        "alert_drop": args.alert_drop,
        "nm": metrics(rec_nm, t, truth, nominal, args.alert_drop, n),
        "ekf_result": metrics(rec_ekf, t, truth, {k: v for k, v in nominal.items() if k in aug},
                              args.alert_drop, n),
    }
    if args.plot:
        if args.param not in nominal:
            raise UsageError(f"--param {args.param}: not a monitored parameter ({', '.join(nominal)})")
        plot(args.plot, t, truth, [rec_nm, rec_ekf], args.param, nominal[args.param], args.alert_drop)
        out["plot"] = args.plot
    if args.json:
        print_json(out)
    else:
        for name, key in (("Nelder-Mead windows", "nm"), ("EKF", "ekf_result")):
            r = out[key]
            sys.stdout.write(f"{name}: {r['estimates']} estimates, {r['cpu_us_per_sample']:.1f} us CPU/sample\n")
            for k, m in r["params"].items():
                sys.stdout.write(f"  {k}: " + ", ".join(f"{a}={b}" for a, b in m.items()) + "\n")
    return 0
