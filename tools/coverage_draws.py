#!/usr/bin/env python3
"""Benchmark: are one design row's standard errors right? Repeated noise draws, z-scores.

Identifies one row of a ``suspid doe`` design (as ``suspid doe`` does: the data-driven start,
the given start at ``--init-scale``, the honest bands) on ``--draws`` noise realisations
(``numpy`` seeds ``--seed0``, ``--seed0 + 1``, ...; the design itself uses its settings' seed
plus the row number) and prints, per free parameter, the mean and standard deviation of the
z-score ``(estimate - truth) / stderr`` (about 0 and 1 when the standard errors are right),
and how many draws put some parameter more than 3 standard errors off (a correct band
misses ``1 - 0.9973^p`` of draws for ``p`` parameters) or outside its reported band.

Next to each it prints the same statistics of the linearised z-score of the same draws
(:func:`tools.doe_noise.linearised_error`: the error the draw's noise puts into the
estimate to first order, over its exact standard error; standard normal by construction), so
a spread away from 1 that the linearised z-scores share is the draws' sampling spread, not
a wrong standard error; and the identifier's standard error of each log-parameter over the
exact one (mean, min-max over the draws; 1 = right).

Usage::

    python tools/coverage_draws.py --model full7 --cost sse --row 17 --noise 0.1
        [--draws 50] [--seed0 200] [--init-scale 0.5]
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only cost here

import argparse
import math

import numpy as np

from estimator.doe import runner
from estimator.doe.design import experiments
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository: tools.*

from tools.doe_noise import linearised_error  # noqa: E402
from estimator.doe.runner import Settings, run_experiment
from suspid.models import get_model
from suspid.models.base import FloatArray


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", required=True)
    ap.add_argument("--cost", default="sse")
    ap.add_argument("--row", type=int, required=True, help="design row (1-based)")
    ap.add_argument("--noise", type=float, required=True)
    ap.add_argument("--init-scale", type=float, default=0.5)
    ap.add_argument("--draws", type=int, default=50)
    ap.add_argument("--seed0", type=int, default=200)
    a = ap.parse_args(argv)
    model = get_model(a.model)
    designs = experiments(model)
    if not 1 <= a.row <= len(designs):
        ap.error(f"--row: expected 1..{len(designs)}, got {a.row}")
    exp = designs[a.row - 1]
    settings = Settings(cost=a.cost, init_scale=a.init_scale, noise=a.noise)
    real = runner.measurement
    lin = linearised_error(model, exp, settings)
    z: list[dict[str, float]] = []
    z_lin: list[FloatArray] = []
    se_ratio: list[FloatArray] = []
    outside = 0
    for seed in range(a.seed0, a.seed0 + a.draws):
        # the row's record with this draw's noise instead of the design's own seed
        runner.measurement = (lambda m, e, noise, _seed, *rest, s=seed, **kw:  # type: ignore[misc]
                              real(m, e, noise, s, *rest, **kw))
        try:
            _, res = run_experiment(model, exp, settings)
        finally:
            runner.measurement = real
        z_lin.append(lin.delta(real(model, exp, a.noise, seed)[0]) / lin.stderr)
        cov = np.asarray(res.cov_log if res.cov_log is not None else
                         np.full((len(lin.free),) * 2, np.nan), dtype=float)
        se_ratio.append(np.sqrt(np.diag(cov)) / lin.stderr)
        z.append({k: (res.params[k] - exp.truth[k]) / se for k, se in (res.stderr or {}).items()
                  if se and math.isfinite(se)})
        if res.bands and any(not ((lo is None or lo <= exp.truth[k])
                                  and (hi is None or exp.truth[k] <= hi))
                             for k, (lo, hi) in res.bands.items()):
            outside += 1
    keys = sorted({k for d in z for k in d})
    Z = np.array([[d.get(k, np.nan) for k in keys] for d in z])
    print(f"{a.model} {a.cost} row {a.row} noise {a.noise:g}, {len(z)} draws (seeds "
          f"{a.seed0}-{a.seed0 + a.draws - 1})")
    ZL = np.array(z_lin)
    R = np.array(se_ratio)
    print("  (z: the fit's; linearised: the same draws' first-order error over its exact "
          "standard error;\n   stderr / exact: the identifier's log-parameter standard error "
          "over the exact one)")
    for i, k in enumerate(keys):
        j = lin.free.index(k)
        print(f"  {k:5s} z mean {np.nanmean(Z[:, i]):+.2f}  sd {np.nanstd(Z[:, i]):.2f}   "
              f"linearised mean {ZL[:, j].mean():+.2f}  sd {ZL[:, j].std():.2f}   stderr / exact "
              f"{np.nanmean(R[:, j]):.3f} ({np.nanmin(R[:, j]):.3f}-{np.nanmax(R[:, j]):.3f})")
    beyond = int(np.sum(np.nanmax(np.abs(Z), axis=1) > 3.0))
    expected = 1.0 - 0.9973 ** len(keys)
    print(f"  draws with some |z| > 3: {beyond}/{len(z)} (linearised: "
          f"{int(np.sum(np.abs(ZL).max(axis=1) > 3.0))}; correct standard errors: "
          f"{100 * expected:.1f} %); outside a reported band: {outside}/{len(z)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
