"""Predictive-maintenance benchmark: sliding-window Nelder-Mead vs the fair EKF, side by side.

Held-out streams (ISO 8608 class C road at 50 km/h, white noise on every channel as a
fraction of its RMS, DBC quantization) with different suspensions, noise levels, wear rates
and wearing parts: quarter cars losing damping (c1) or spring stiffness (k1), the demo's
quantization-only damper wear, a half car losing front damping and a full car losing
front-left damping (250 Hz, positions and roads measured); both estimators run
through ``suspid compare``'s library call (:func:`estimator.stream.compare.compare`) with the
same free parameters (dampers and springs; masses known), starts (nominal) and alert rule.
Printed per stream: tracking RMSE of the wearing part (the value the alerts are decided on),
the RMS of its error over its stated stderr (1 = honest), first alert delay after the true
70 % crossing, false alarms, first forecast (lead time before the crossing, error of its
predicted time, whether its 90 % interval holds the truth), CPU per sample, and the EKF's NIS.

Usage::

    python tools/bench_maintenance.py                  # every stream (~1-2 min on one core)
    python tools/bench_maintenance.py --only demo,fast # a subset, by key
    python tools/bench_maintenance.py --json           # one JSON object
    python tools/bench_maintenance.py --window-drift none   # the constant window
    python tools/bench_maintenance.py --drift          # the window with a linear drift of
                                                       # the wearing part only (default: every
                                                       # free strut damper and spring drifts)
"""
from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from estimator.stream.config import WindowOptions
from estimator.stream.compare import compare
from estimator.stream.wear_streams import Stream, damper_wear
from estimator.stream.window import SlidingWindowIdentifier
from suspid.excitation import iso8608_profile, time_grid
from suspid.models import get_model
from suspid.simulate import outputs, road_matrix, simulate_states

TABLE1 = {"m1": 275.0, "c1": 1120.0, "k1": 150000.0, "m2": 27.0, "c2": 3100.0, "k2": 310000.0}
SOFT = {"m1": 300.0, "c1": 1500.0, "k1": 20000.0, "m2": 40.0, "c2": 300.0, "k2": 200000.0}


@dataclass(frozen=True)
class Case:
    """One held-out stream."""

    key: str
    name: str
    params: dict[str, float] | None   # quarter2 parameters (None: the model's defaults)
    noise: float | None       # white noise, fraction of each channel's RMS (None: 2 DBC steps)
    duration: float
    wear_start: float
    wear_end: float
    wear_to: float            # the part at wear_end, fraction of nominal (1.0: no wear)
    seed: int
    part: str = "c1"          # the wearing parameter
    model: str = "quarter2"


CASES = [
    Case("stiff", "stiff (Table 1), 2 % noise, c1 -50 % over 90 s", TABLE1, 0.02, 150.0, 30.0,
         120.0, 0.5, 3),
    Case("soft", "soft, 1 % noise, c1 -50 % over 100 s", SOFT, 0.01, 130.0, 20.0, 120.0, 0.5, 5),
    Case("fast", "stiff, 5 % noise, fast wear c1 -50 % over 50 s", TABLE1, 0.05, 110.0, 30.0,
         80.0, 0.5, 7),
    Case("stable", "soft, 2 % noise, no wear", SOFT, 0.02, 90.0, 30.0, 80.0, 1.0, 11),
    Case("demo", "demo (suspid compare's default): quantization only, c1 -50 % over 130 s",
         None, None, 150.0, 20.0, 150.0, 0.5, 0),
    Case("demo60", "README demo (tools/demo.py's compare): quantization only, c1 -50 % over 40 s",
         None, None, 60.0, 20.0, 60.0, 0.5, 0),
    Case("spring", "soft, 2 % noise, spring k1 -40 % over 80 s", SOFT, 0.02, 120.0, 20.0,
         100.0, 0.6, 13, part="k1"),
    Case("half4", "half car, 1 % noise, front damper c1 -50 % over 50 s (250 Hz)", None, 0.01,
         80.0, 20.0, 70.0, 0.5, 4, model="half4"),
    Case("full7", "full car, 1 % noise, front-left damper c1 -50 % over 50 s (250 Hz)", None,
         0.01, 80.0, 20.0, 70.0, 0.5, 6, model="full7"),
]

#: the full car's known parameters: masses, inertias and geometry
FULL7_KNOWN = ("m", "Ix", "Iy", "m1", "m2", "m3", "m4", "a1", "a2", "w1", "w2")


def half4_stream(case: Case) -> Stream:
    """Half car on an ISO 8608 class C road at 50 km/h (rear wheel on the front's road,
    delayed by the wheelbase), 250 Hz, front damper c1 losing damping linearly; white noise
    of ``case.noise`` x each channel's RMS on x, delta, x1, x2 and both roads."""
    m = get_model("half4")
    p0 = m.defaults()
    t = time_grid(case.duration, 250.0)
    wb = p0["a1"] + p0["a2"]
    r1, r1d = iso8608_profile(t, "C", 50.0, case.seed, lag=0.0, lead=wb + 1.0)
    r2, r2d = iso8608_profile(t, "C", 50.0, case.seed, lag=wb, lead=wb + 1.0)
    road = {"r1": r1, "r1_dot": r1d, "r2": r2, "r2_dot": r2d}
    U = road_matrix(m, t, road)
    c_true = p0["c1"] * np.interp(t, [case.wear_start, case.wear_end], [1.0, case.wear_to])
    X = np.empty((t.size, m.n_states))
    x = np.zeros(m.n_states)
    step = max(1, int(round(0.05 * 250.0)))
    affine = m.affine(p0, ["c1"])
    for i0 in range(0, t.size - 1, step):
        i1 = min(i0 + step, t.size - 1)
        p = dict(p0, c1=float(c_true[(i0 + i1) // 2]))
        seg = slice(i0, i1 + 1)
        X[seg] = simulate_states(m, p, t[seg], U[seg], x, affine=affine)
        x = X[i1]
    out = outputs(m, p0, X, U)
    rng = np.random.default_rng(case.seed + 1)
    data = {}
    for c in ("x", "delta", "x1", "x2", "r1", "r2"):
        y = np.asarray(road[c] if c in road else out[c], dtype=float)
        data[c] = y + rng.normal(0.0, float(case.noise or 0.0) * float(np.std(y)), t.size)
    truth = {k: np.full(t.size, v) for k, v in p0.items()}
    truth["c1"] = c_true
    return Stream(t, data, truth, dict(p0))


def full7_stream(case: Case) -> Stream:
    """Full car on an ISO 8608 class C road at 50 km/h (independent left and right tracks,
    each rear wheel on its front's track delayed by the wheelbase), 250 Hz, front-left damper
    c1 losing damping linearly; white noise of ``case.noise`` x each channel's noise-free RMS
    on the seven positions and the four roads (as :func:`half4_stream`: no accelerations or
    road velocities measured), no quantization."""
    m = get_model("full7")
    kw: dict[str, Any] = dict(duration=case.duration, fs=250.0, c_end_fraction=case.wear_to,
                              wear_start=case.wear_start, wear_end=case.wear_end,
                              seed=case.seed, damper=case.part, channels=tuple(m.coords),
                              quantize=False)
    clean = damper_wear(m, noise={c: 0.0 for c in tuple(m.coords) + m.input_names}, **kw)
    noise = {c: float(case.noise or 0.0) * float(np.std(v)) for c, v in clean.data.items()}
    s = damper_wear(m, noise=noise, **kw)
    s.data = {c: v for c, v in s.data.items() if not c.endswith("_dot")}
    return s


def make_stream(case: Case) -> Stream:
    """The case's stream: noise set relative to each channel's noise-free RMS."""
    if case.model == "half4":
        return half4_stream(case)
    if case.model == "full7":
        return full7_stream(case)
    m = get_model("quarter2")
    kw: dict[str, Any] = dict(duration=case.duration, fs=500.0, params=case.params,
                              c_end_fraction=case.wear_to, wear_start=case.wear_start,
                              wear_end=case.wear_end, seed=case.seed, damper=case.part)
    if case.noise is None:
        return damper_wear(m, **kw)
    clean = damper_wear(m, noise={c: 0.0 for c in ("x1", "x2", "x1_ddot", "r", "r_dot")},
                        quantize=False, **kw)
    noise = {c: case.noise * float(np.std(v)) for c, v in clean.data.items()}
    return damper_wear(m, noise=noise, **kw)


def known(case: Case, nominal: dict[str, float]) -> dict[str, float]:
    """The parameters held fixed: masses (and the half and full cars' inertias and geometry);
    the demo also holds the tyre, as ``suspid compare`` does by default."""
    if case.model == "half4":
        return {k: nominal[k] for k in ("m", "I", "m1", "m2", "a1", "a2")}
    if case.model == "full7":
        return {k: nominal[k] for k in FULL7_KNOWN}
    if case.key in ("demo", "demo60"):
        return {k: nominal[k] for k in ("m1", "m2", "c2", "k2")}
    return {k: nominal[k] for k in ("m1", "m2")}


def run_case(case: Case, window_options: dict[str, Any] | None = None) -> dict[str, Any]:
    """Both estimators on one case; the metrics of the wearing part on each side."""
    m = get_model(case.model)
    s = make_stream(case)
    base = dict(s.nominal)
    fix = known(case, base)
    nominal = {k: v for k, v in base.items() if k not in fix and k in m.param_names}
    out, _ = compare(m, s.t, s.data, s.truth, fix=fix, nominal=nominal, source=case.name,
                     window=WindowOptions(**(window_options or {})))
    row: dict[str, Any] = {"case": case.name, "key": case.key, "part": case.part}
    for side, key in (("nm", "nm"), ("ekf", "ekf_result")):
        r = out[key]
        c1 = r["params"][case.part]
        fa = sum(p.get("false_alarms", 0) for p in r["params"].values())
        ff = sum(p.get("false_forecasts", 0) for p in r["params"].values())
        row[side] = {"rmse_pct": c1.get("rmse_pct"), "alert_delay_s": c1.get("alert_delay_s"),
                     "error_over_stderr": c1.get("error_over_stderr_rms"),
                     "false_alarms": fa, "false_forecasts": ff,
                     "forecast_lead_s": c1.get("forecast_lead_s"),
                     "forecast_error_s": c1.get("forecast_first_error_s"),
                     "forecast_contains": c1.get("forecast_first_contains"),
                     "cpu_us_per_sample": r["cpu_us_per_sample"], "estimates": r["estimates"],
                     "skipped": r["skipped"], "nis": r.get("nis")}
    row["crossing_t"] = out["nm"]["params"][case.part].get("crossing_t")
    return row


def solver_check(case: Case, window_options: dict[str, Any] | None) -> dict[str, Any]:
    """Both drift solvers on every window of one case (the same constant fit each time).

    The Gauss-Newton solver's result goes on (the run itself is the monitor's with that
    solver); per window the first-order one is computed too. Returns the RMS and largest
    difference of the drifting parameters' end values over the Gauss-Newton stderr (the
    stated one, floor included), the median and range of the ratio of their stderr_fit, and
    the mean CPU per window of each solver (ms).
    """
    rows: list[tuple[float, float, float, float]] = []
    orig = SlidingWindowIdentifier._drift_fit

    def both(self: SlidingWindowIdentifier, prob: Any, t_end: float, width: float,
             p_const: Any, drift: list[str], out: Any) -> None:
        o1 = copy.deepcopy(out)
        c0 = time.process_time()
        self.first_order_drift = True
        orig(self, prob, t_end, width, p_const, drift, o1)
        c1 = time.process_time()
        self.first_order_drift = False
        orig(self, prob, t_end, width, p_const, drift, out)
        c2 = time.process_time()
        del self.first_order_drift        # back to the class default
        for k in drift:
            rows.append(((o1.params[k] - out.params[k]) / out.stderr[k],
                         o1.stderr_fit[k] / out.stderr_fit[k], c1 - c0, c2 - c1))

    SlidingWindowIdentifier._drift_fit = both  # type: ignore[method-assign]
    try:
        run_case(case, window_options)
    finally:
        SlidingWindowIdentifier._drift_fit = orig  # type: ignore[method-assign]
    a = np.array(rows)
    return {"key": case.key, "windows": int(a.shape[0]),
            "diff_over_stderr_rms": float(np.sqrt(np.mean(a[:, 0] ** 2))),
            "diff_over_stderr_max": float(np.abs(a[:, 0]).max()),
            "stderr_fit_ratio": [float(np.median(a[:, 1])), float(a[:, 1].min()),
                                 float(a[:, 1].max())],
            "cpu_ms_linear": 1e3 * float(a[:, 2].mean()),
            "cpu_ms_gauss_newton": 1e3 * float(a[:, 3].mean())}


def _f(v: Any, fmt: str) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    return format(v, fmt)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--cases", type=int, default=len(CASES), help="run the first N cases")
    ap.add_argument("--only", default=None, metavar="KEYS",
                    help="comma-separated case keys (" + ", ".join(c.key for c in CASES) + ")")
    ap.add_argument("--road-fusion", type=float, default=None, metavar="HZ",
                    help="sliding window: fuse each road displacement with its velocity's "
                         "integral above HZ (WindowConfig.road_fusion_hz; default 1.5 x "
                         "the highest natural frequency, 0: off)")
    ap.add_argument("--road-lowpass", type=float, default=None, metavar="HZ",
                    help="sliding window: zero-phase low-pass of each road displacement at HZ "
                         "(WindowConfig.road_lowpass_hz; default 0: off)")
    ap.add_argument("--drift", action="store_true",
                    help="sliding window: refit the wearing part (only) with a linear drift "
                         "over each window (as --window-drift part), its estimate at the "
                         "window end")
    ap.add_argument("--window-drift", default=None, metavar="NAMES",
                    help="sliding window: parameters fitted with a linear drift over each "
                         "window (WindowConfig.drift): comma-separated names, 'part' (the "
                         "wearing part) or 'none' (constant window); default the monitor's "
                         "(every free damper and spring of the struts)")
    ap.add_argument("--drift-rate-sd", type=float, default=None, metavar="PER_S",
                    help="with a drift: prior sd of each window's relative rate around "
                         "the recent estimates' (WindowConfig.drift_rate_sd; 0: none)")
    ap.add_argument("--drift-chunk", type=float, default=None, metavar="S",
                    help="with --drift: chunk over which the drift is held constant "
                         "(WindowConfig.drift_chunk_s)")
    ap.add_argument("--solver-check", action="store_true",
                    help="run both drift solvers on every window (first-order and "
                         "Gauss-Newton, SlidingWindowIdentifier.first_order_drift) and print "
                         "how far apart "
                         "their end values are, in stated stderr, and their CPU")
    args = ap.parse_args(argv)
    cases = CASES[:args.cases]
    if args.only:
        keys = [k.strip() for k in args.only.split(",") if k.strip()]
        unknown = [k for k in keys if k not in {c.key for c in CASES}]
        if unknown:
            ap.error(f"--only: unknown case {', '.join(unknown)}")
        cases = [c for c in CASES if c.key in keys]
    opts: dict[str, Any] = {}
    if args.road_fusion is not None:
        opts["road_fusion_hz"] = args.road_fusion
    if args.road_lowpass is not None:
        opts["road_lowpass_hz"] = args.road_lowpass
    rows = []
    for c in cases:
        o = dict(opts)
        wd = "part" if args.drift else args.window_drift
        if wd is not None:
            names = tuple(x.strip() for x in wd.split(",") if x.strip())
            o["drift"] = ((c.part,) if names == ("part",) else
                          () if names in ((), ("none",)) else names)
        if args.drift_rate_sd is not None:
            o["drift_rate_sd"] = args.drift_rate_sd
        if args.drift_chunk is not None:
            o["drift_chunk_s"] = args.drift_chunk
        if args.solver_check:
            chk = solver_check(c, o or None)
            sys.stdout.write(json.dumps(chk) + "\n")
            sys.stdout.flush()
            continue
        rows.append(run_case(c, o or None))
    if args.solver_check:
        return 0
    if args.json:
        json.dump({"cases": rows}, sys.stdout, indent=1)
        sys.stdout.write("\n")
        return 0
    for r in rows:
        sys.stdout.write(f"\n[{r['key']}] {r['case']} (true {r['part']} crossing: "
                         f"{_f(r['crossing_t'], '.1f')} s)\n")
        sys.stdout.write(f"  {'':28s}{'Nelder-Mead':>14s}{'EKF':>10s}{'ratio':>8s}\n")
        for label, key, fmt in ((f"{r['part']} RMSE (% of truth)", "rmse_pct", ".2f"),
                                ("error / stated stderr (RMS)", "error_over_stderr", ".2f"),
                                ("alert delay (s)", "alert_delay_s", ".1f"),
                                ("false alarms", "false_alarms", "d"),
                                ("forecasts without crossing", "false_forecasts", "d"),
                                ("first forecast lead (s)", "forecast_lead_s", ".1f"),
                                ("forecast time error (s)", "forecast_error_s", "+.1f"),
                                ("90 % interval holds truth", "forecast_contains", ""),
                                ("CPU per sample (us)", "cpu_us_per_sample", ".1f"),
                                ("estimates / skipped", None, ""),
                                ("EKF mean NIS per dof", "nis", ".2f")):
            if key is None:
                a = f"{r['nm']['estimates']}/{r['nm']['skipped']}"
                b = f"{r['ekf']['estimates']}/{r['ekf']['skipped']}"
                sys.stdout.write(f"  {label:28s}{a:>14s}{b:>10s}\n")
                continue
            a, b = r["nm"][key], r["ekf"][key]
            ratio = (f"{a / b:.2f}" if isinstance(a, float) and isinstance(b, float) and b
                     and key in ("rmse_pct", "cpu_us_per_sample") else "")
            sys.stdout.write(f"  {label:28s}{_f(a, fmt):>14s}{_f(b, fmt):>10s}{ratio:>8s}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
