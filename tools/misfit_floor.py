"""Measure the monitor's per-window noise-floor ratio on correct and on wrong fits.

For every model and noise level (fraction of each channel's std, on every channel and the
road) a random-road record is simulated (``suspid simulate``) and monitored (``suspid
monitor --jsonl``); the largest ``noise_floor_ratio`` of any fitted window and channel is
reported per run. Correct runs fix what the monitor needs at the truth (or nothing); the
``wrong`` runs fix the body mass at twice the truth with the tyre fixed at the truth, the
case a misfit warning must catch. The threshold ``MISFIT_RATIO`` of
:mod:`estimator.stream.misfit` is chosen above every correct run.

Usage::

    python tools/misfit_floor.py [--seeds 1,2] [--noise 0.1,0.2,0.3,0.5] [--duration 30] [--json]
    python tools/misfit_floor.py --wear [--seeds 1,2] [--duration 30]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from estimator.stream.misfit import MISFIT_WINDOWS

#: fixes of the correct runs per model (truth = the model defaults), and of the wrong runs
CASES: dict[str, dict[str, list[str]]] = {
    "quarter1": {"free": [], "mass": ["m=300"], "wrong": ["m=600"]},
    "quarter2": {"free": [], "mass": ["m1=300", "m2=40"],
                 "wrong": ["m1=600", "m2=40", "c2=300", "k2=200000"]},
    "half4": {"free": [], "mass": ["m=1200", "I=1500", "m1=40", "m2=40"],
              "wrong": ["m=2400", "I=1500", "m1=40", "m2=40"]},
    "full7": {"free": []},
}


def _suspid(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "suspid", *args], capture_output=True, text=True,
                          check=False)


def run_case(model: str, fixes: list[str], noise: float, seed: int, duration: float,
             tmp: Path, wear: bool = False) -> dict[str, object]:
    """Simulate one record and monitor it; the largest ratio and the warning (if any).

    ``wear``: instead of ``suspid simulate``, the damper-wear stream of the benchmarks
    (:func:`estimator.stream.wear_streams.damper_wear`: c1 loses 0.5 %/s, the
    sensor noise 2 quantization steps on every channel and on the road, quantized as the
    DBC sends it); ``noise`` is then not used.
    """
    csv = tmp / f"{model}_{noise}_{seed}_{wear}.csv"
    if wear:
        from estimator.stream.wear_streams import damper_wear
        from suspid.io.csvio import write_measurement
        from suspid.models import get_model

        # the damper loses 0.5 %/s of its nominal (the must-show stream's rate)
        s = damper_wear(get_model(model), duration=duration, wear_start=0.1 * duration,
                        c_end_fraction=max(0.5, 1.0 - 0.005 * 0.9 * duration),
                        seed=seed, damper="c" if model == "quarter1" else "c1")
        write_measurement(csv, s.t, s.data)
    else:
        sim = _suspid("simulate", "--model", model, "--scenario", "iso8608", "--duration",
                      str(duration), "--fs", "500", "--speed", "50", "--noise", str(noise),
                      "--seed", str(seed), "--out", str(csv))
        if sim.returncode != 0:
            raise SystemExit(sim.stderr)
    args = ["monitor", "--model", model, "--input", str(csv), "--jsonl", "--no-inspection"]
    for f in fixes:
        args += ["--fix", f]
    mon = _suspid(*args)
    if mon.returncode != 0:
        raise SystemExit(mon.stderr)
    lines = [json.loads(x) for x in mon.stdout.splitlines() if x.strip()]
    ratios = [max(d["noise_floor_ratio"].values()) for d in lines
              if d["type"] == "estimate" and d.get("noise_floor_ratio")]
    warned = [d for d in lines if d["type"] == "warning" and d.get("kind") == "misfit"]
    # the level a warning needs MISFIT_WINDOWS windows in a row above: the largest of the
    # smallest ratio in any MISFIT_WINDOWS consecutive fitted windows
    n = MISFIT_WINDOWS
    persistent = max((min(ratios[i:i + n]) for i in range(len(ratios) - n + 1)), default=None)
    return {"model": model, "fix": fixes, "noise": noise, "seed": seed, "windows": len(ratios),
            "persistent": persistent, "ratios": ratios,
            "max_ratio": max(ratios) if ratios else None,
            "median_ratio": sorted(ratios)[len(ratios) // 2] if ratios else None,
            "warned": bool(warned)}


def _show(r: dict[str, object]) -> str:
    """One run's counts and ratios as text."""
    if r["max_ratio"] is None:
        return f"{r['windows']} windows fitted (every window skipped), warned {r['warned']}"
    pers = "-" if r["persistent"] is None else f"{r['persistent']:.3f}"
    return (f"{r['windows']} windows, ratio median {r['median_ratio']:.3f} max "
            f"{r['max_ratio']:.3f}, over {MISFIT_WINDOWS} windows in a row {pers}, "
            f"warned {r['warned']}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1,2")
    ap.add_argument("--noise", default="0.1,0.2,0.3,0.5")
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--models", default=",".join(CASES))
    ap.add_argument("--wear", action="store_true",
                    help="the damper-wear streams (road noise, quantized) instead of simulate")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as d:
        if a.wear:
            for model in a.models.split(","):
                for fixes in (CASES[model].get("mass", []),):
                    for seed in (int(x) for x in a.seeds.split(",")):
                        r = run_case(model, fixes, 0.0, seed, a.duration, Path(d), wear=True)
                        r["kind"] = "wear"
                        rows.append(r)
                        if not a.json:
                            print(f"{model:9s} wear  seed {seed}: {_show(r)}", flush=True)
            if a.json:
                print(json.dumps(rows))
            return
        for model in a.models.split(","):
            for kind, fixes in CASES[model].items():
                for noise in (float(x) for x in a.noise.split(",")):
                    for seed in (int(x) for x in a.seeds.split(",")):
                        r = run_case(model, fixes, noise, seed, a.duration, Path(d))
                        r["kind"] = kind
                        rows.append(r)
                        if not a.json:
                            print(f"{model:9s} {kind:5s} noise {noise:.2f} seed {seed}: "
                                  f"{_show(r)}", flush=True)
    if a.json:
        print(json.dumps(rows))


if __name__ == "__main__":
    main()
