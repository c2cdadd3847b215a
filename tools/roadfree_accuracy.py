"""Measure the road-unknown identification: accuracy, honesty of its stderr, and wall time.

For every model and sensor set, random-road drives (ISO 8608 class C at 50 km/h, 30 s) are
simulated exactly, reduced to the sensor set (``production``: body accelerations and ride
heights; ``accelerometers``: body and wheel accelerometers), given Gaussian noise (a fraction
of each channel's std) and identified with the road unknown, masses, inertias and geometry
held at the truth. Per model and set it prints the largest relative error of any strut's
damper or spring over the drives, the RMS of the normalised errors ``(estimate - truth) /
stderr`` (1 when the stated uncertainty is right), the median wall time of one fit, and
how many drives the fit called a misfit (the body equations leave clearly more than the
noise; ``misfit ratio`` the largest noise-floor ratio of any body row over the drives).
``--effect`` simulates every drive with an effect the linear model lacks (as
``suspid simulate --effect``), so the misfit column shows whether the fit notices it.

Usage::

    python tools/roadfree_accuracy.py [--models quarter2,half4] [--sets production]
                                      [--drives 10] [--noise 0.02] [--fs 500]
                                      [--effect coulomb_friction:F=60]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from estimator.identify.params import Parameters
from estimator.identify.roadfree import fit_road_unknown
from suspid.excitation import make_scenario
from suspid.effects import inject
from suspid.io.csvio import Measurement
from suspid.models import get_model
from suspid.simulate import simulate


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default="quarter1,quarter2,half4,full7")
    ap.add_argument("--sets", default="production,accelerometers")
    ap.add_argument("--drives", type=int, default=10)
    ap.add_argument("--noise", type=float, default=0.02)
    ap.add_argument("--fs", type=float, default=500.0)
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--effect", action="append", default=[],
                    help="simulate with this effect (suspid simulate --effect syntax)")
    args = ap.parse_args()
    print(f"{'model':8} {'sensors':14} {'max |error| %':>14} {'z rms':>6} {'fit ms':>7} "
          f"{'misfit':>7} {'misfit ratio':>12}")
    for name in args.models.split(","):
        model = get_model(name)
        p = model.defaults()
        fix = {s.name: p[s.name] for s in model.params if s.kind in ("mass", "inertia", "length")}
        struts = [n for s in model.strut_sites(p) for n in (s.c_name, s.k_name) if n]
        for sensors in args.sets.split(","):
            errs, z, times, undetermined = [], [], [], set()
            misfits, worst = 0, 0.0
            for seed in range(args.drives):
                t, road, x0 = make_scenario(model, "iso8608", duration=args.duration, fs=args.fs,
                                            params=p, seed=seed, v_kmh=50.0)
                ch = (inject(model, args.effect).simulate(p, t, road, x0) if args.effect
                      else simulate(model, p, t, road, x0))
                rng = np.random.default_rng(seed + 1000)
                meas = {c: ch[c] + args.noise * np.std(ch[c]) * rng.standard_normal(t.size)
                        for c in model.channel_set(sensors)}
                t0 = time.perf_counter()
                r = fit_road_unknown(model, Measurement(t=t, measured=meas),
                                     Parameters.for_model(model, fix=fix))
                times.append(time.perf_counter() - t0)
                undetermined |= set(struts) & set(r.undetermined or [])
                misfits += bool(r.misfit)
                worst = max([worst, *(v[0] for v in (r.misfit or {}).values())])
                for n in struts:
                    errs.append(abs(r.params[n] / p[n] - 1))
                    if n in r.stderr:
                        z.append((r.params[n] - p[n]) / r.stderr[n])
            zr = float(np.sqrt(np.mean(np.square(z)))) if z else float("nan")
            if undetermined:
                print(f"{name:8} {sensors:14} not determined: {', '.join(sorted(undetermined))}")
                continue
            print(f"{name:8} {sensors:14} {100 * max(errs):14.3f} {zr:6.2f} "
                  f"{1e3 * float(np.median(times)):7.1f} {misfits:3d}/{args.drives:<3d} "
                  f"{worst:12.3g}")


if __name__ == "__main__":
    main()
