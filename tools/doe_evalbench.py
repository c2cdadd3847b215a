"""Cost of one identifier evaluation (``OutputErrorProblem.normalized_ss``), per case.

Usage::

    python tools/doe_evalbench.py [--repeat 300] [--no-jacobian]

Cases: ``half4`` and ``quarter2`` free responses (DoE row 14, 20 s at 100 Hz = 2001
samples, positions + velocities) with the initial state known or estimated (variable
projection), and the seed's Table 1 quarter car over the speed bump (3 s at 1 kHz = 3001
samples, initial state estimated: what ``suspid identify`` runs). Prints the median wall
and CPU time per evaluation in microseconds; the process's own CPU time is what the
machine's load does not distort. Each call takes the next of :data:`N_POINTS` parameter
sets a few parts per million apart (a version that caches evaluations per problem is timed
evaluating, not looking up).

Then, per free-response case, the central-difference Jacobian of the residual vector in
every parameter (``2 n`` evaluations) two ways: one evaluation after another
(``residual_vector`` per point) and :func:`~estimator.identify.jacobian_log` (batched in
versions that stacked points), in microseconds per Jacobian. The file also runs as a script against
another version's package (``PYTHONPATH=DIR python tools/doe_evalbench.py``).
"""
from __future__ import annotations

import argparse
import functools
import itertools
import json
import math
import statistics
import time
from typing import Any, Callable

import numpy as np

from estimator.doe.design import experiments
from estimator.identify import OutputErrorProblem, jacobian_log
from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement
from suspid.models import get_model
from suspid.simulate import simulate


def _cases() -> list[tuple[str, Any, dict[str, float]]]:
    out = []
    t = np.arange(2001) / 100.0
    for name in ("half4", "quarter2"):
        m = get_model(name)
        e = experiments(m)[13]
        truth, x0 = e.truth, e.x0
        clean = simulate(m, truth, t, None, x0)
        meas = Measurement(t=t, road={}, measured={c: clean[c] for c in m.state_names})
        p = {k: v * 1.05 for k, v in truth.items()}
        out.append((f"{name} free response, x0 known, 2001 samples",
                    OutputErrorProblem(m, meas, cost="frobenius", x0=x0), p))
        out.append((f"{name} free response, x0 estimated, 2001 samples",
                    OutputErrorProblem(m, meas, cost="frobenius", x0="estimate"), p))
    T1 = {"m1": 275.0, "c1": 1120.0, "k1": 150000.0, "m2": 27.0, "c2": 3100.0, "k2": 310000.0}
    m = get_model("quarter2")
    tb, road, x0 = make_scenario(m, "bump", duration=3.0, fs=1000.0, params=T1)
    clean = simulate(m, T1, tb, road, x0)
    meas = Measurement(t=tb, road=road, measured={c: clean[c] for c in m.state_names})
    p = {k: v * 1.05 for k, v in T1.items()}
    out.append(("quarter2 speed bump (Table 1), x0 estimated, sse, 3001 samples",
                OutputErrorProblem(m, meas, cost="sse", x0="estimate"), p))
    return out


def jacobian_one_by_one(problem: OutputErrorProblem, p: dict[str, float],
                        free: list[str] | None = None, rel_step: float = 1e-5) -> Any:
    """Central differences of the residual in every log-parameter of ``free`` (default all
    of ``p``), one ``residual_vector`` at a time: the reference the batched Jacobian is
    timed and tested against."""
    cols = []
    for k in (free if free is not None else list(p)):
        pp, pm = dict(p), dict(p)
        pp[k] = p[k] * math.exp(rel_step)
        pm[k] = p[k] * math.exp(-rel_step)
        cols.append((problem.residual_vector(pm) - problem.residual_vector(pp)) / (2 * rel_step))
    return np.column_stack(cols)


#: distinct parameter sets each timed function cycles through (more than any problem caches)
N_POINTS = 64


def _cycle(fn: Callable[[dict[str, float]], object], p: dict[str, float]) -> Callable[[], object]:
    """``fn`` of the next of :data:`N_POINTS` sets ``p * (1 + 1e-6 i)`` on each call."""
    points = itertools.cycle([{k: v * (1.0 + 1e-6 * i) for k, v in p.items()}
                              for i in range(N_POINTS)])
    return lambda: fn(next(points))


def _time(fn: Callable[[], object], repeat: int, rounds: int) -> dict[str, float]:
    """Median wall and CPU time (us) per call of ``fn`` over ``rounds`` x ``repeat`` calls."""
    walls, cpus = [], []
    fn()
    for _ in range(rounds):
        w, c = time.perf_counter(), time.process_time()
        for _ in range(repeat):
            fn()
        walls.append((time.perf_counter() - w) / repeat * 1e6)
        cpus.append((time.process_time() - c) / repeat * 1e6)
    return {"wall_us": statistics.median(walls), "cpu_us": statistics.median(cpus)}


def _jacobian_log_all(problem: OutputErrorProblem, p: dict[str, float]) -> Any:
    """:func:`~estimator.identify.jacobian_log` in every parameter of ``p``."""
    return jacobian_log(problem, p, list(p))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=300)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--no-jacobian", action="store_true", help="only the single evaluations")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    res = {}
    cases = _cases()
    timed: list[tuple[str, Callable[[], object], int]] = [
        (label, _cycle(prob.normalized_ss, p), args.repeat)
        for label, prob, p in cases]
    if not args.no_jacobian:
        rep = max(args.repeat // 10, 1)
        for label, prob, p in cases:
            if "free response" not in label:
                continue
            short = label.split(",")[0] + "," + label.split(",")[1]
            timed.append((f"{short}: Jacobian ({2 * len(p)} ev.), one by one",
                          _cycle(functools.partial(jacobian_one_by_one, prob), p), rep))
            timed.append((f"{short}: Jacobian ({2 * len(p)} ev.), jacobian_log",
                          _cycle(functools.partial(_jacobian_log_all, prob), p), rep))
    for label, fn, repeat in timed:
        res[label] = _time(fn, repeat, args.rounds)
        if not args.json:
            print(f"{label:>72}: {res[label]['wall_us']:8.0f} us wall {res[label]['cpu_us']:8.0f} us CPU",
                  flush=True)
    if args.json:
        print(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
