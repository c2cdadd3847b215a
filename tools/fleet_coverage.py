"""Coverage of the fleet's 90 % forecast interval, and the alpha-lambda accuracy, on a
simulated fleet of vans driven like real ones.

Each van is a ``quarter2`` whose damper wears linearly from about its nominal 1500 N s/m to
the limit (70 %) on a known day ``T`` (60 to 200 days after its first drive). Its drives come
at uneven intervals (exponential gaps, mean ``--gap`` days), each with its own body mass
(300 to 480 kg: the payload) and its own damper scatter (the drive's true ``c1`` is the wear
line times ``1 + e``, ``e`` normal with a standard deviation drawn per van from 2 to 3 %:
temperature, the road's amplitude). Every drive is simulated over an ISO 8608 road and
logged as a production car would (body acceleration and ride height with 2 % noise, no
road), identified with the road unknown and the spring held (the body mass and the damper
per drive), and the van is summarised as ``suspid fleet`` does
(:func:`estimator.fleet.analysis.summarize_vehicle`) from its drives up to the time of
the prediction. Each van also drives a distance every day (its mean drawn from 80 to 300 km,
each day's distance gamma-distributed around it with a 30 % coefficient of variation, from
its own random stream so the days results do not change), and each drive carries its
odometer (the drive's distance from :func:`estimator.fleet.drive.drive_distance`), so the
forecast's crossing in km (the trend against the odometer) is checked against the van's
true odometer on its crossing day. The wear here follows time, not distance: the km
interval must also absorb the usage's day-to-day variation.

Printed:

coverage
    the share of forecasts whose 90 % interval holds the true crossing day ``T``, with the
    predictions made at ``lambda`` = 0.5 and 0.8 of the van's life (``t = lambda T``); and
    the share whose km interval holds the van's true odometer at ``T``.
alpha-lambda
    the prognostics metric of NASA's ProgPy (``alpha_lambda``): at ``lambda`` = 0.5, the share
    of vans whose predicted remaining life ``crossing_t - t`` is within ``alpha`` = 20 % of
    the true one ``T - t`` (a van without a forecast fails it).

Usage::

    OPENBLAS_NUM_THREADS=1 python tools/fleet_coverage.py --vans 120 --seed 1
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from estimator.alerts.engine import AlertConfig
from estimator.fleet.analysis import summarize_vehicle
from estimator.fleet.drive import classify, drive_distance
from estimator.identify import Parameters
from estimator.identify.roadfree import fit_road_unknown
from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement
from suspid.models import get_model
from suspid.simulate import simulate

DAY_S = 86400.0
T0 = 1.79e9
NOMINAL = 1500.0
DROP = 0.3
BASE = {"m1": 300.0, "c1": NOMINAL, "k1": 20000.0, "m2": 40.0, "c2": 300.0, "k2": 200000.0}


@dataclass
class Van:
    """One simulated van: its true crossing day, its drives' records and its odometer
    (km at the end of each day from day 0)."""

    name: str
    life_days: float
    records: list[dict[str, Any]]
    odometer_km: np.ndarray

    def odometer_m(self, day: float) -> float:
        """The odometer (m) ``day`` days after the first drive (linear within a day)."""
        days = np.arange(self.odometer_km.size, dtype=float)
        return 1e3 * float(np.interp(day, days, self.odometer_km))


def drive_record(van: str, day: float, c1: float, m1: float, seed: int, duration: float,
                 fs: float, odometer_m: float = math.nan) -> dict[str, Any]:
    """Simulate one production-car drive and identify it with the road unknown.

    Parameters
    ----------
    van : str
        Vehicle name.
    day : float
        Days after the van's first drive.
    c1, m1 : float
        The drive's true damper (N s/m) and body mass (kg).
    seed : int
        Road and noise seed.
    duration, fs : float
        Drive length (s) and sample rate (Hz).
    odometer_m : float
        The van's odometer at the drive's start (m; NaN: no odometer signal).

    Returns
    -------
    dict
        A fleet drive record (``path``, ``vehicle``, ``t`` epoch s, ``status``, ``result``).
    """
    model = get_model("quarter2")
    p = {**BASE, "c1": c1, "m1": m1}
    t, road, x0 = make_scenario(model, "iso8608", duration=duration, fs=fs, params=p,
                                v_kmh=50.0, seed=seed)
    out = simulate(model, p, t, road, x0)
    rng = np.random.default_rng(seed + 7919)
    meas = Measurement(t=t, road={}, measured={
        c: out[c] + rng.standard_normal(t.size) * 0.02 * np.std(out[c])
        for c in model.channel_set("production")},
        aux={} if math.isnan(odometer_m) else {"odometer": odometer_m + 50.0 / 3.6 * t})
    res = fit_road_unknown(model, meas, Parameters.for_model(model, fix={"k1": BASE["k1"]}))
    result = res.to_json()
    status, error = classify(result)
    return {"path": f"{van}/{day:.3f}.csv", "vehicle": van, "t": T0 + day * DAY_S,
            "status": status, "error": error, "result": result, "sha256": f"{van}-{seed}",
            **drive_distance(meas)}


def usage(rng: np.random.Generator, days: int = 400) -> np.ndarray:
    """A van's odometer (km) at the end of each day: mean 80 to 300 km a day, each day's
    distance gamma-distributed with a 30 % coefficient of variation (module docstring)."""
    mean = float(rng.uniform(80.0, 300.0))
    shape = 1.0 / 0.3 ** 2
    daily = rng.gamma(shape, mean / shape, days)
    return float(rng.uniform(5_000.0, 150_000.0)) + np.concatenate([[0.0], np.cumsum(daily)])


def make_van(i: int, rng: np.random.Generator, gap: float, upto: float, duration: float,
             fs: float, seed: int = 0) -> Van:
    """A van's drives from day 0 up to ``upto`` of its life (module docstring); its usage
    from a stream of its own (``seed``, ``i``)."""
    life = float(rng.uniform(60.0, 200.0))
    c0 = NOMINAL * float(rng.uniform(0.95, 1.05))
    limit = (1.0 - DROP) * NOMINAL
    scatter = float(rng.uniform(0.02, 0.03))
    days = [0.0]
    while True:
        nxt = days[-1] + float(rng.exponential(gap))
        if nxt > upto * life:
            break
        days.append(nxt)
    van = Van(f"VAN-{i:04d}", life, [], usage(np.random.default_rng((seed, i))))
    for k, d in enumerate(days):
        c1 = (c0 + (limit - c0) * d / life) * (1.0 + scatter * float(rng.standard_normal()))
        m1 = float(rng.uniform(300.0, 480.0))
        van.records.append(drive_record(van.name, d, c1, m1, 100_000 * i + k, duration, fs,
                                        van.odometer_m(d)))
    return van


def predict(van: Van, lam: float, rule: AlertConfig
            ) -> tuple[float, float, float, float, tuple[float, float, float] | None] | None:
    """The fleet's forecast at ``t = lam x life`` from the drives up to then: ``(t_pred,
    crossing, low, high)`` in days after the first drive and the crossing in km (odometer,
    ``None`` without one); ``None`` without a forecast."""
    t_pred = lam * van.life_days
    recs = [r for r in van.records if (r["t"] - T0) / DAY_S <= t_pred]
    s = summarize_vehicle(van.name, recs, rule)
    fc = s.forecasts.get("c1")
    if fc is None:
        return None
    km = None if fc.crossing_m is None else (fc.crossing_m[0] / 1e3, fc.crossing_m[1] / 1e3,
                                             fc.crossing_m[2] / 1e3)
    return (t_pred, (fc.crossing_t - T0) / DAY_S, (fc.crossing_t_low - T0) / DAY_S,
            (fc.crossing_t_high - T0) / DAY_S, km)


def _coverage(hits: int, n: int) -> tuple[float, float]:
    """Share of ``n`` intervals that held the truth and its binomial standard error."""
    if not n:
        return math.nan, math.nan
    cov = hits / n
    return cov, math.sqrt(cov * (1 - cov) / n)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vans", type=int, default=120)
    ap.add_argument("--gap", type=float, default=4.0, help="mean days between drives")
    ap.add_argument("--duration", type=float, default=12.0, help="drive length (s)")
    ap.add_argument("--fs", type=float, default=200.0, help="sample rate (Hz)")
    ap.add_argument("--alpha", type=float, default=0.2)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    rule = AlertConfig.per_drive(nominal={"c1": NOMINAL}, drop=DROP, horizon_days=10_000.0)
    wall = time.perf_counter()
    vans = [make_van(i, rng, args.gap, 0.8, args.duration, args.fs, args.seed)
            for i in range(args.vans)]
    n_drives = sum(len(v.records) for v in vans)
    n_ok = sum(r["status"] == "ok" for v in vans for r in v.records)
    sim_s = time.perf_counter() - wall
    print(f"fleet: {args.vans} vans, {n_drives} drives ({n_ok} ok) of {args.duration:g} s, "
          f"gaps exponential with mean {args.gap:g} d, crossing day 60-200, damper scatter "
          f"2-3 % per drive, payload 300-480 kg; simulated and identified in {sim_s:.0f} s")
    for lam in (0.5, 0.8):
        hits = n_fc = ontime = km_hits = n_km = 0
        widths, km_widths = [], []
        for v in vans:
            fc = predict(v, lam, rule)
            if fc is None:
                continue
            t_pred, tc, lo, hi, km = fc
            n_fc += 1
            if km is not None:
                true_km = v.odometer_m(v.life_days) / 1e3
                n_km += 1
                km_hits += km[1] <= true_km <= km[2]
                km_widths.append((km[2] - km[1]) / (true_km - v.odometer_m(t_pred) / 1e3))
            hits += lo <= v.life_days <= hi
            widths.append((hi - lo) / (v.life_days - t_pred))
            true_rul, rul = v.life_days - t_pred, tc - t_pred
            ontime += abs(rul - true_rul) <= args.alpha * true_rul
        cov, se = _coverage(hits, n_fc)
        print(f"lambda {lam:.1f}: {n_fc} of {args.vans} vans with a forecast; 90 % interval "
              f"holds the true day in {hits} ({100 * cov:.1f} % +/- {100 * se:.1f}); "
              f"alpha-lambda (alpha {args.alpha:g}): {ontime} of {args.vans} "
              f"({100 * ontime / args.vans:.1f} %); median interval width "
              f"{100 * float(np.median(widths)) if widths else math.nan:.0f} % of the "
              "remaining life")
        kcov, kse = _coverage(km_hits, n_km)
        print(f"lambda {lam:.1f} km: {n_km} of {n_fc} forecasts with a crossing in km; 90 % "
              f"interval holds the true odometer in {km_hits} ({100 * kcov:.1f} % +/- "
              f"{100 * kse:.1f}); median interval width "
              f"{100 * float(np.median(km_widths)) if km_widths else math.nan:.0f} % of the "
              "remaining distance")
    return 0


if __name__ == "__main__":
    sys.exit(main())
