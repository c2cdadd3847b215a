"""Measure what ``suspid identify`` leaves on correct fits and on fits with wrong fixed values.

For every model, road scenario (bump, ISO 8608) and noise level (fraction of each channel's
std, on every channel and the road; 0 = noise-free) a record is simulated (``suspid
simulate``, 5 s at 200 Hz) and identified as ``suspid identify`` does by default; with
``--can`` the noise-free records are also sent through ``suspid encode`` (quantized as the
DBC sends them) and read back. Per run it prints ``success``, ``nfev`` and the largest
noise-floor ratio and excess share of any fitted channel
(:func:`estimator.identify.misfit.misfit_measures`). Correct runs fix the masses needed to make
the rest identifiable at the truth; ``all2x`` runs hold every parameter at twice the truth
(masses at the truth: nothing free), ``body2x`` runs the body mass at twice the truth with
the other masses at the truth and the rest free. ``MISFIT_FLOOR`` and ``MISFIT_SHARE`` of
:mod:`estimator.identify.misfit` separate the two groups.

Usage::

    python tools/identify_misfit.py [--models quarter1,half4] [--noise 0,0.1,0.5]
                                    [--cases ok,all2x,body2x] [--can] [--seed 3]
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

from estimator.identify import OutputErrorProblem, Parameters, fit, fit_from_starts
from estimator.identify.inputs import read_input
from estimator.identify.misfit import misfit_measures
from suspid.models import get_model

#: masses held at the truth so that the rest is identifiable (the model defaults are the truth)
MASSES: dict[str, list[str]] = {"quarter1": ["m"], "quarter2": ["m1", "m2"],
                                "half4": ["m", "I", "m1", "m2"],
                                "full7": ["m", "Ix", "Iy", "m1", "m2", "m3", "m4"]}
#: the body mass of each model
BODY: dict[str, str] = {"quarter1": "m", "quarter2": "m1", "half4": "m", "full7": "m"}


def fixes(model: str, case: str) -> dict[str, float]:
    """The ``--fix`` values of one case (SI)."""
    truth = get_model(model).defaults()
    held = {k: truth[k] for k in MASSES[model]}
    if case == "all2x":
        return {k: (v if k in MASSES[model] or get_model(model).spec(k).kind == "length"
                    else 2.0 * v) for k, v in truth.items()}
    if case == "body2x":
        held[BODY[model]] = 2.0 * truth[BODY[model]]
    return held


def run(model: str, path: Path, fix: dict[str, float]) -> str:
    """Identify ``path`` as ``suspid identify`` does by default; one line of measures."""
    m = get_model(model)
    meas, _ = read_input(str(path), m, None, None)
    problem = OutputErrorProblem(m, meas)
    params = Parameters.for_model(m, fix=fix)
    res = fit_from_starts(problem, params,
                          lambda s: fit(problem, s, polish=True, multistart=4)[0],
                          keep_init=False)
    mm = misfit_measures(problem, res.params)
    ratio = max((r for r, _ in mm.values()), default=float("nan"))
    share = max((sh for _, sh in mm.values()), default=float("nan"))
    return f"success={res.success!s:5} nfev={res.nfev:6d} ratio={ratio:9.3g} share={share:9.3g}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default="quarter1,quarter2,half4,full7")
    ap.add_argument("--scenarios", default="bump,iso8608")
    ap.add_argument("--noise", default="0,0.1,0.5")
    ap.add_argument("--cases", default="ok,all2x,body2x")
    ap.add_argument("--can", action="store_true", help="also the quantized CAN logs (noise 0)")
    ap.add_argument("--seed", type=int, default=3)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for model in a.models.split(","):
            for scen in a.scenarios.split(","):
                for noise in (float(v) for v in a.noise.split(",")):
                    csv = Path(tmp) / f"{model}_{scen}_{noise}.csv"
                    subprocess.run([sys.executable, "-m", "suspid", "simulate", "--model", model,
                                    "--scenario", scen, "--duration", "5", "--fs", "200",
                                    "--noise", str(noise), "--seed", str(a.seed),
                                    "--out", str(csv)], check=True, capture_output=True)
                    paths = [("csv", csv)]
                    if a.can and noise == 0:
                        log = csv.with_suffix(".log")
                        subprocess.run([sys.executable, "-m", "suspid", "encode", "--input",
                                        str(csv), "--model", model, "--out", str(log)],
                                       check=True, capture_output=True)
                        paths.append(("can", log))
                    for kind, path in paths:
                        for case in a.cases.split(","):
                            line = run(model, path, fixes(model, case))
                            print(f"{case:6s} {model:8s} {scen:7s} noise {noise:<4g} {kind:3s} "
                                  f"{line}", flush=True)


if __name__ == "__main__":
    main()
