"""Predictive-maintenance benchmark: sliding-window Nelder-Mead vs the fair EKF, side by side.

Held-out quarter-car streams (ISO 8608 class C road at 50 km/h, white noise on every channel
as a fraction of its RMS, DBC quantization) with different suspensions, noise levels and wear
rates; both estimators run through ``suspid compare``'s library call
(:func:`estimator.stream.compare.compare`) with the same free parameters (dampers and
springs; masses known), starts (nominal) and alert rule. Printed per stream: c1 tracking RMSE
(the value the alerts are decided on), first alert delay after the true 70 % crossing,
false alarms, first forecast (lead time before the crossing, error of its predicted time,
whether its 90 % interval holds the truth), CPU per sample, and the EKF's NIS.

Usage::

    python tools/bench_maintenance.py            # the default streams (~1-2 min on one core)
    python tools/bench_maintenance.py --json     # one JSON object
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from estimator.stream.compare import compare
from estimator.stream.wear_streams import Stream, damper_wear
from suspid.models import get_model

TABLE1 = {"m1": 275.0, "c1": 1120.0, "k1": 150000.0, "m2": 27.0, "c2": 3100.0, "k2": 310000.0}
SOFT = {"m1": 300.0, "c1": 1500.0, "k1": 20000.0, "m2": 40.0, "c2": 300.0, "k2": 200000.0}


@dataclass(frozen=True)
class Case:
    """One held-out stream."""

    name: str
    params: dict[str, float]
    noise: float              # white noise, fraction of each channel's RMS
    duration: float
    wear_start: float
    wear_end: float
    wear_to: float            # c1 at wear_end, fraction of nominal (1.0: no wear)
    seed: int


CASES = [
    Case("stiff (Table 1), 2 % noise, c1 -50 % over 90 s", TABLE1, 0.02, 150.0, 30.0, 120.0, 0.5, 3),
    Case("soft, 1 % noise, c1 -50 % over 100 s", SOFT, 0.01, 130.0, 20.0, 120.0, 0.5, 5),
    Case("stiff, 5 % noise, fast wear c1 -50 % over 50 s", TABLE1, 0.05, 110.0, 30.0, 80.0, 0.5, 7),
    Case("soft, 2 % noise, no wear", SOFT, 0.02, 90.0, 30.0, 80.0, 1.0, 11),
]


def make_stream(case: Case) -> Stream:
    """The case's stream: noise set relative to each channel's noise-free RMS."""
    m = get_model("quarter2")
    kw: dict[str, Any] = dict(duration=case.duration, fs=500.0, params=case.params,
                              c_end_fraction=case.wear_to, wear_start=case.wear_start,
                              wear_end=case.wear_end, seed=case.seed)
    clean = damper_wear(m, noise={c: 0.0 for c in ("x1", "x2", "x1_ddot", "r", "r_dot")},
                        quantize=False, **kw)
    noise = {c: case.noise * float(np.std(v)) for c, v in clean.data.items()}
    return damper_wear(m, noise=noise, **kw)


def run_case(case: Case) -> dict[str, Any]:
    """Both estimators on one case; the c1 metrics of each."""
    m = get_model("quarter2")
    s = make_stream(case)
    fix = {"m1": case.params["m1"], "m2": case.params["m2"]}
    nominal = {k: v for k, v in case.params.items() if k not in fix}
    out, _ = compare(m, s.t, s.data, s.truth, fix=fix, nominal=nominal, source=case.name)
    row: dict[str, Any] = {"case": case.name}
    for side, key in (("nm", "nm"), ("ekf", "ekf_result")):
        r = out[key]
        c1 = r["params"]["c1"]
        fa = sum(p.get("false_alarms", 0) for p in r["params"].values())
        ff = sum(p.get("false_forecasts", 0) for p in r["params"].values())
        row[side] = {"rmse_pct": c1.get("rmse_pct"), "alert_delay_s": c1.get("alert_delay_s"),
                     "false_alarms": fa, "false_forecasts": ff,
                     "forecast_lead_s": c1.get("forecast_lead_s"),
                     "forecast_error_s": c1.get("forecast_first_error_s"),
                     "forecast_contains": c1.get("forecast_first_contains"),
                     "cpu_us_per_sample": r["cpu_us_per_sample"], "estimates": r["estimates"],
                     "skipped": r["skipped"], "nis": r.get("nis")}
    row["crossing_t"] = out["nm"]["params"]["c1"].get("crossing_t")
    return row


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
    args = ap.parse_args(argv)
    rows = [run_case(c) for c in CASES[:args.cases]]
    if args.json:
        json.dump({"cases": rows}, sys.stdout, indent=1)
        sys.stdout.write("\n")
        return 0
    for r in rows:
        sys.stdout.write(f"\n{r['case']} (true crossing: {_f(r['crossing_t'], '.1f')} s)\n")
        sys.stdout.write(f"  {'':28s}{'Nelder-Mead':>14s}{'EKF':>10s}{'ratio':>8s}\n")
        for label, key, fmt in (("c1 RMSE (% of truth)", "rmse_pct", ".2f"),
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
