#!/usr/bin/env python3
"""Benchmark: the forward model through the model's affine pieces vs through the model.

Every consumer of the forward model can take ``A``, ``B`` (and ``M^-1``) from the model's
affine pieces (:meth:`suspid.models.base.SuspensionModel.affine`) or from the model itself
(``state_space``, ``mass_inverse``). For every model (default: all built-in) this prints the
CPU time per call of each consumer both ways, side by side, and the ratio pieces/model:

* ``identify``: one prediction of the identifier (``OutputErrorProblem.normalized_ss``,
  2 s at 500 Hz, positions and velocities, initial state estimated) at a new set of
  dampers and springs;
* ``simulate``: :func:`suspid.simulate.simulate` of the same record;
* ``nlsim``: :func:`suspid.nlsim.simulate_effects` with Coulomb friction (0.4 s);
* ``pieces``: building the pieces once (``model.affine``) against one ``state_space``.

The EKF has no model path left to compare: it steps ``[A | B]`` from the pieces.

Usage::

    python tools/bench_forward.py [--models quarter2 full7] [--repeat 5]
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from typing import Callable

import numpy as np

from estimator.identify import OutputErrorProblem
from suspid.effects import make_effect
from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement
from suspid.models import BUILTIN, get_model
from suspid.nlsim import simulate_effects
from suspid.simulate import simulate


def cpu_per_call(fs: list[Callable[[], object]], n: int, repeat: int) -> list[float]:
    """Best of ``repeat`` runs of the CPU seconds per call of each of ``fs`` (``n`` calls a
    run); the functions take turns, so a change of the machine's load hits them alike."""
    best = [np.inf] * len(fs)
    for _ in range(repeat):
        for i, f in enumerate(fs):
            c0 = time.process_time()
            for _ in range(n):
                f()
            best[i] = min(best[i], (time.process_time() - c0) / n)
    return [float(b) for b in best]


def bench(name: str, repeat: int) -> dict[str, tuple[float, float]]:
    """``consumer -> (seconds via the pieces, seconds via the model)`` for one model."""
    m = get_model(name)
    p = m.defaults()
    t, road, x0 = make_scenario(m, "iso8608", duration=2.0, fs=500.0, params=p, v_kmh=40, seed=1)
    sim = simulate(m, p, t, road, x0)
    chans = list(m.coords) + [f"{c}_dot" for c in m.coords]
    meas = Measurement(t=t, road=road, measured={c: sim[c] for c in chans}, source="bench")
    aff = m.affine(p)
    off = replace(aff, exact=False)  # pieces that never apply: every call goes to the model
    rng = np.random.default_rng(0)
    sets = [dict(p, **{k: p[k] * float(np.exp(rng.normal(0, 0.2))) for k in aff.names})
            for _ in range(16)]
    out: dict[str, tuple[float, float]] = {}

    def cycle() -> Callable[[], dict[str, float]]:
        it = iter(sets * 100000)
        return lambda: next(it)

    def both(run: Callable[..., object], n: int) -> tuple[float, float]:
        ps, po = cycle(), cycle()
        a, b = cpu_per_call([lambda: run(ps(), aff), lambda: run(po(), off)], n, repeat)
        return a, b

    problems = {id(aff): OutputErrorProblem(m, meas, affine=aff),
                id(off): OutputErrorProblem(m, meas, affine=off)}
    out["identify"] = both(lambda q, pc: problems[id(pc)].normalized_ss(q), 16)
    out["simulate"] = both(lambda q, pc: simulate(m, q, t, road, x0, affine=pc), 16)
    eff = [make_effect("coulomb_friction", F=50.0)]
    n = 200
    short = {k: v[:n] for k, v in road.items()}
    out["nlsim"] = both(lambda q, pc: simulate_effects(m, q, eff, t[:n], short, x0, affine=pc), 8)
    a, b = cpu_per_call([lambda: m.affine(p), lambda: m.state_space(p)], 8, repeat)
    out["pieces"] = (a, b)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", nargs="+", default=list(BUILTIN))
    ap.add_argument("--repeat", type=int, default=5, help="runs per timing, best kept")
    args = ap.parse_args()
    w = sys.stdout.write
    w(f"{'model':>8} {'consumer':>9} {'pieces':>10} {'model':>10} {'ratio':>6}\n")
    for name in args.models:
        for what, (a, b) in bench(name, args.repeat).items():
            w(f"{name:>8} {what:>9} {a * 1e6:8.1f}us {b * 1e6:8.1f}us {a / b:6.2f}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
