#!/usr/bin/env python
"""The road unknown against the road measured, side by side in one run: monitor CPU per
sample and identify's time on the same record.

Usage (from the repository root)::

    python tools/bench_roadfree.py [--duration 150] [--record 30] [--repeat 3] [--json]

``monitor``
    The damper-wear stream of ``suspid compare`` (quarter2, ISO 8608 class C at 50 km/h,
    500 Hz, c1 falling from 1500 to 750 N s/m between 20 s and the end; quantized as the DBC
    sends it, the node's noise), carrying both what the road-measured path needs (x1, x2,
    x1_ddot, r, r_dot) and what a production car sends (x1_ddot and the ride height d).
    Each estimator -- the sliding window and the EKF, with the road measured and with the
    road unknown -- streams it in-process through the monitor's wiring (tracker, alerts,
    forecasts; masses and tyre fixed, c1 and k1 free); CPU per stream sample (the minimum
    over ``--repeat`` runs, for a shared machine), c1 RMS error of the values the alerts
    use and the alert delay after the 70 % crossing.
``identify``
    ``--record`` seconds of the same stream with a sound damper (constant parameters, so
    both fits have one truth) as a measurement CSV, identified
    by ``suspid identify --road measured`` and ``--road unknown`` (the same free c1, k1),
    in a subprocess, end to end (fastest of ``--repeat``; each uses the channels its path
    takes from the record), and the same command in this process (``fit_s``: reading the
    CSV and the identification, no interpreter start).
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from estimator.stream.compare import metrics, run_one  # noqa: E402
from estimator.stream.pipeline import monitor_spec  # noqa: E402
from estimator.stream.wear_streams import Stream, damper_wear  # noqa: E402
from suspid.cli import main as cli_main  # noqa: E402
from suspid.io.csvio import write_measurement  # noqa: E402
from suspid.models import get_model  # noqa: E402

FIX = {"m1": 300.0, "m2": 40.0, "c2": 300.0, "k2": 200000.0}
MEASURED = ("x1", "x2", "x1_ddot", "r", "r_dot")
UNKNOWN = ("x1_ddot", "d")


def _stream(duration: float, wear_to: float = 0.5) -> Stream:
    m = get_model("quarter2")
    return damper_wear(m, duration=duration, fs=500.0, seed=0, c_end_fraction=wear_to,
                       channels=("x1", "x2", "x1_ddot", "d"))


def bench_monitor(s: Stream, repeat: int) -> dict[str, Any]:
    """CPU per sample of the four estimators on the stream (module docstring)."""
    m = get_model("quarter2")
    out: dict[str, Any] = {}
    for road, chans in (("measured", MEASURED), ("unknown", UNKNOWN)):
        data = {c: s.data[c] for c in chans}
        for base in ("nm", "ekf"):
            best = None
            for _ in range(repeat):
                spec = monitor_spec(m, fix=FIX, baseline=base, fs=500.0, road=road,
                                    inspection=False)
                rec = run_one(spec, s.t, data)
                if best is None or rec.cpu_s < best[0].cpu_s:
                    best = (rec, spec)
            assert best is not None
            rec, spec = best
            met = metrics(rec, s.t, s.truth, spec.alert.nominal, 0.3, s.t.size)
            c1 = met["params"]["c1"]
            out[f"{base}/{road}"] = {
                "cpu_us_per_sample": round(met["cpu_us_per_sample"], 2),
                "estimates": met["estimates"], "window_s": spec.config.window_s,
                "c1_rmse_pct": round(c1["rmse_pct"], 3),
                "c1_alert_delay_s": c1["alert_delay_s"],
                "c1_forecast_lead_s": c1.get("forecast_lead_s")}
    return out


def bench_identify(s: Stream, record_s: float, repeat: int, tmp: Path) -> dict[str, Any]:
    """identify's time, road measured vs unknown, on the same record (module docstring)."""
    n = int(record_s * 500.0) + 1
    csv = tmp / "record.csv"
    write_measurement(csv, s.t[:n], {c: s.data[c][:n] for c in set(MEASURED) | set(UNKNOWN)})
    fix = [a for k, v in FIX.items() for a in ("--fix", f"{k}={v:g}")]
    out: dict[str, Any] = {"record_s": record_s, "samples": n}
    for road in ("measured", "unknown"):
        walls = []
        res: dict[str, Any] = {}
        for _ in range(repeat):
            w0 = time.perf_counter()
            r = subprocess.run([sys.executable, "-m", "suspid", "identify", "--model", "quarter2",
                                "--input", str(csv), *fix, "--road", road, "--json"],
                               capture_output=True, text=True, cwd=ROOT)
            walls.append(time.perf_counter() - w0)
            if r.returncode != 0:
                raise SystemExit(r.stderr)
            res = json.loads(r.stdout)
        fits = []
        for _ in range(repeat):   # the same command in this process: no interpreter start
            w0 = time.perf_counter()
            with contextlib.redirect_stdout(io.StringIO()), \
                    contextlib.redirect_stderr(io.StringIO()):
                cli_main(["identify", "--model", "quarter2", "--input", str(csv), *fix,
                          "--road", road, "--json"])
            fits.append(time.perf_counter() - w0)
        out[road] = {"wall_s_end_to_end": round(min(walls), 3), "fit_s": round(min(fits), 4),
                     "c1": res["params"]["c1"], "k1": res["params"]["k1"],
                     "stderr_c1": res["stderr"].get("c1")}
    out["fit_measured_over_unknown"] = round(out["measured"]["fit_s"] / out["unknown"]["fit_s"], 1)
    return out


def _s(v: float | None) -> str:
    return "none" if v is None else f"{v:+.1f} s"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=150.0, help="stream length (s), default 150")
    ap.add_argument("--record", type=float, default=30.0,
                    help="identify: record length (s), default 30")
    ap.add_argument("--repeat", type=int, default=3, help="runs per figure, fastest kept")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as d:
        # identify first: in-process it is measured in a fresh interpreter's state
        idf = bench_identify(_stream(a.record, wear_to=1.0), a.record, a.repeat, Path(d))
        out = {"monitor": bench_monitor(_stream(a.duration), a.repeat), "identify": idf}
    if a.json:
        print(json.dumps(out))
        return 0
    print(f"monitor, {a.duration:g} s at 500 Hz (CPU per sample, fastest of {a.repeat}):")
    print(f"  {'':14} {'road measured':>16} {'road unknown':>16}")
    for base, label in (("nm", "sliding window"), ("ekf", "EKF")):
        r1, r2 = out["monitor"][f"{base}/measured"], out["monitor"][f"{base}/unknown"]
        print(f"  {label:14} {r1['cpu_us_per_sample']:>13.2f} us {r2['cpu_us_per_sample']:>13.2f} us"
              f"   (c1 RMSE {r1['c1_rmse_pct']:.2f} % / {r2['c1_rmse_pct']:.2f} %, alert "
              f"{_s(r1['c1_alert_delay_s'])} / {_s(r2['c1_alert_delay_s'])} after the crossing)")
    idf = out["identify"]
    print(f"identify, {a.record:g} s record: end to end "
          f"{idf['measured']['wall_s_end_to_end']:.2f} s (road measured) vs "
          f"{idf['unknown']['wall_s_end_to_end']:.2f} s (road unknown); in-process "
          f"{idf['measured']['fit_s']:.3f} s vs {idf['unknown']['fit_s']:.4f} s "
          f"({idf['fit_measured_over_unknown']}x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
