#!/usr/bin/env python3
"""Benchmark: is a design row's miss its noise realisation? The linearised estimation error.

Near the truth an output-error estimate is linear in the noise
(:func:`tools.doe_noise.linearised_error`): its log-parameter error is
``delta = (J^T J)^-1 J^T e`` (``J`` the sensitivity of the cost's weighted channels to the
log-parameters at the truth, ``e`` the weighted noise added to the record), with the exact
covariance ``C = (J^T J)^-1 J^T S J (J^T J)^-1`` (``S`` the per-channel noise variance the
record was made with: ``noise`` x the clean channel's std, squared). ``delta_k / sqrt(C_kk)``
is then a standard normal value for every realisation; its size for one realisation says
how extreme that realisation is, independently of the fit and of the identifier's standard
errors.

``--row all`` prints one line per row instead: on the design's own realisations, the largest
linearised ``|z|`` of each row, the values beyond 3 and ``delta' C^-1 delta``.

For one row of a ``suspid doe`` design and one noise realisation (default: the design's own,
``numpy`` seed = the settings' seed + the row number) prints, per free parameter, the
linearised z-score ``delta_k / sqrt(C_kk)``; with ``--fit`` also the identifier's (as
``suspid doe`` runs it: the fit's log error over its own standard error), that standard
error over the exact one, and the fit's distance from the linearised prediction in its
standard errors (small: the fit is at the minimum the linear model predicts); the parameter
with the largest linearised ``|z|`` (or ``--param``) split by channel (each channel's part of
the z-score and of its variance) with the effective number of samples and the largest single
sample's part; the squared Mahalanobis distance ``delta' C^-1 delta`` with its chi-square tail; and the
realisation's noise per channel against the noise model (its std over the intended one,
lag-1 autocorrelation, Kolmogorov-Smirnov p-value against the normal). With
``--draws N`` also the mean and std of each linearised z-score over ``N`` further
realisations (seeds ``--seed0``, ...; no fits, a few ms each).

Usage::

    python tools/linearised_error.py --model full7 --cost sse --row 17 --noise 0.1 [--fit]
        [--seed S] [--param k4] [--draws 25 --seed0 200]
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only cost here

import argparse
import math

import numpy as np
from scipy.stats import chi2, kstest, norm

from estimator.doe import runner
from estimator.doe.design import Experiment, experiments
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository: tools.*

from tools.doe_noise import linearised_error  # noqa: E402
from estimator.doe.runner import Settings, free_names, measurement, run_experiment
from estimator.identify.result import IdentResult
from suspid.models import SuspensionModel, get_model


def fit_row(model: SuspensionModel, exp: Experiment, settings: Settings, seed: int
            ) -> IdentResult:
    """Identify row ``exp`` as ``suspid doe`` does, on the realisation of ``seed``."""
    real = runner.measurement
    runner.measurement = (lambda m, e, nz, _seed, *rest, **kw:  # type: ignore[assignment]
                          real(m, e, nz, seed, *rest, **kw))
    try:
        _, res = run_experiment(model, exp, settings)
    finally:
        runner.measurement = real
    return res


def summarise(model: SuspensionModel, designs: list[Experiment], settings: Settings) -> None:
    """Print, for every row on the design's own realisation, the largest linearised
    ``|z|``, the values beyond 3 and ``delta' C^-1 delta`` with its chi-square tail."""
    print(f"{model.name} {settings.cost} noise {settings.noise:g}, every row on its own "
          "realisation (seed = settings' seed + row)")
    total = 0.0
    for exp in designs:
        lin = linearised_error(model, exp, settings)
        delta = lin.delta(measurement(model, exp, settings.noise, settings.seed + exp.id)[0])
        z = delta / lin.stderr
        d2 = float(delta @ np.linalg.solve(lin.cov, delta))
        total += d2
        far = ", ".join(f"{k} {v:+.2f}" for k, v in zip(lin.free, z) if abs(v) > 3.0)
        print(f"  row {exp.id:2d}: max |z| {float(np.max(np.abs(z))):.2f}, d' C^-1 d {d2:5.1f} "
              f"(tail {chi2.sf(d2, len(lin.free)):.2g})" + (f"; beyond 3: {far}" if far else ""))
    dof = len(designs) * len(free_names(model, settings.free_masses))
    print(f"  sum of d' C^-1 d {total:.1f} (chi-square with {dof} degrees of freedom: "
          f"{dof} +- {math.sqrt(2 * dof):.0f})")


def main(argv: list[str] | None = None) -> int:
    """Print the linearised error of one row's realisation (see the module docstring)."""
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--model", required=True)
    ap.add_argument("--cost", default="sse")
    ap.add_argument("--row", required=True,
                    help="design row (1-based), or 'all': one summary line per row")
    ap.add_argument("--noise", type=float, required=True)
    ap.add_argument("--seed", type=int, default=None,
                    help="noise seed (default: the design's, settings' seed + row)")
    ap.add_argument("--param", default=None,
                    help="parameter to split by channel (default: the largest linearised |z|)")
    ap.add_argument("--fit", action="store_true", help="also identify the row and compare")
    ap.add_argument("--draws", type=int, default=0)
    ap.add_argument("--seed0", type=int, default=200)
    a = ap.parse_args(argv)
    if not a.noise > 0:
        ap.error(f"--noise: expected a fraction > 0, got {a.noise}")
    model = get_model(a.model)
    designs = experiments(model)
    settings = Settings(cost=a.cost, noise=a.noise)
    if a.row == "all":
        summarise(model, designs, settings)
        return 0
    row = int(a.row) if a.row.isdigit() else 0
    if not 1 <= row <= len(designs):
        ap.error(f"--row: expected 1..{len(designs)} or all, got {a.row}")
    exp = designs[row - 1]
    seed = settings.seed + exp.id if a.seed is None else a.seed
    lin = linearised_error(model, exp, settings)
    se = lin.stderr
    e = lin.noise_of(measurement(model, exp, a.noise, seed)[0])
    delta = lin.gain @ e
    z = delta / se
    print(f"{a.model} {a.cost} row {row} noise {a.noise:g}, seed {seed}")
    res = fit_row(model, exp, settings, seed) if a.fit else None
    head = f"  {'name':5s} {'z linear':>9s}"
    if res is not None:
        head += f" {'z fit':>7s} {'se fit/exact':>12s} {'|fit-lin|/se':>12s}"
    print(head)
    for i, k in enumerate(lin.free):
        line = f"  {k:5s} {z[i]:+9.2f}"
        if res is not None and res.cov_log is not None:
            act = math.log(res.params[k] / exp.truth[k])
            se_fit = math.sqrt(float(np.asarray(res.cov_log)[i, i]))
            line += f" {act / se_fit:+7.2f} {se_fit / se[i]:12.3f} {abs(act - delta[i]) / se_fit:12.3f}"
        print(line)
    d2 = float(delta @ np.linalg.solve(lin.cov, delta))
    print(f"  d' C^-1 d = {d2:.1f} for {len(lin.free)} values: chi-square tail "
          f"{chi2.sf(d2, len(lin.free)):.2g}")
    if a.param is not None and a.param not in lin.free:
        ap.error(f"--param: expected one of {', '.join(lin.free)}, got {a.param!r}")
    j = int(np.argmax(np.abs(z))) if a.param is None else lin.free.index(a.param)
    g = lin.gain[j] / se[j]
    nch = len(lin.channels)
    part = (g * e).reshape(-1, nch)
    share = (g ** 2 * np.tile(lin.sigma ** 2, part.shape[0])).reshape(-1, nch)
    print(f"  {lin.free[j]} (z {z[j]:+.2f}, two-sided tail {2 * norm.sf(abs(z[j])):.2g} per value) "
          "by channel:")
    for c, name in enumerate(lin.channels):
        v = float(share[:, c].sum())
        s = float(part[:, c].sum())
        print(f"    {name:9s} part of z {s:+6.2f}, of its variance {v:5.3f}"
              + (f", alone {s / math.sqrt(v):+.2f} sigma" if v > 0 else ""))
    w = share.reshape(-1) / share.sum()
    print(f"    effective samples {1.0 / float(np.sum(w ** 2)):.0f}, the largest single "
          f"sample's part of z {float(np.max(np.abs(part))):.3f}")
    print("  the realisation's noise per channel: std over the intended one, lag-1 "
          "autocorrelation,\n    Kolmogorov-Smirnov p against the normal")
    un = e.reshape(-1, nch) / lin.sigma
    for c, name in enumerate(lin.channels):
        x = un[:, c]
        print(f"    {name:9s} {float(np.std(x)):.3f}  {float(np.corrcoef(x[1:], x[:-1])[0, 1]):+.3f}"
              f"  {float(kstest(x, 'norm').pvalue):.2f}")
    if a.draws > 0:
        Z = np.array([lin.delta(measurement(model, exp, a.noise, s)[0]) / se
                      for s in range(a.seed0, a.seed0 + a.draws)])
        print(f"  linearised z over {a.draws} realisations (seeds {a.seed0}-"
              f"{a.seed0 + a.draws - 1}):")
        for i, k in enumerate(lin.free):
            print(f"    {k:5s} mean {Z[:, i].mean():+.2f}  sd {Z[:, i].std():.2f}")
        print(f"    sd {Z.std(axis=0).min():.2f}-{Z.std(axis=0).max():.2f} per value, "
              f"pooled {Z.std():.2f}; realisations with some |z| > 3: "
              f"{int(np.sum(np.abs(Z).max(axis=1) > 3))}/{a.draws}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
