"""Noise robustness of ``suspid diagnose``: an undeclared effect at several noise levels and seeds.

The records are those of the worked example in ``docs/closing-the-loop.md`` (the seed's
Table 1 quarter car over the speed bump, 2 s at 250 Hz, masses known, the other parameters
started at 0.7 x the truth), made exactly as ``suspid simulate ... --noise N --seed S``
makes them (:func:`tools.synthetic_record.synthetic_record` with ``noise_seed=S``).

Usage::

    python tools/noise_sweep.py                          # friction 60 N and 150 N
    python tools/noise_sweep.py --effect coulomb_friction:F=150 --noise 0.03 --seeds 1-8
    python tools/noise_sweep.py --json                   # one JSON object per record

The Markdown table has one row per effect and noise level: how many records named the
injected effect, the wrong one or none, the range of the effect's parameters and of the
c1 error (baseline -> augmented) where it was named, and the records where c1 and k1 are
within 5 % of the truth.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any, Sequence

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository: tools.*

from tools.synthetic_record import synthetic_record  # noqa: E402
from estimator.diagnose.core import diagnose
from estimator.identify import Parameters
from suspid.models import get_model

#: the seed's Table 1 quarter car (SI)
TABLE1 = dict(m1=275.0, k1=150000.0, c1=1120.0, m2=27.0, k2=310000.0, c2=3100.0)
ROUGH = {k: 0.7 * TABLE1[k] for k in ("c1", "k1", "c2", "k2")}


def run_one(spec: str, noise: float, seed: int, fs: float = 250.0, duration: float = 2.0) -> dict[str, Any]:
    """Diagnose one record: ``spec`` injected, white noise ``noise`` drawn from ``seed``."""
    meas = synthetic_record("quarter2", [spec], "bump", params=TABLE1, fs=fs, duration=duration,
                            noise=noise, seed=seed, noise_seed=seed)
    model = get_model("quarter2")
    params = Parameters.for_model(model, fix={"m1": TABLE1["m1"], "m2": TABLE1["m2"]}, init=ROUGH)
    t0 = time.perf_counter()
    out = diagnose(model, meas, params).to_json()
    b, a = out["baseline"]["params"], out["augmented"]["params"]
    return {"effect_injected": spec, "noise": noise, "seed": seed, "effect": out["effect"],
            "c1_baseline": b["c1"] / TABLE1["c1"] - 1, "c1": a["c1"] / TABLE1["c1"] - 1,
            "k1": a["k1"] / TABLE1["k1"] - 1, "verdict": out["evidence"].get("verdict", ""),
            "seconds": time.perf_counter() - t0}


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        out += list(range(int(lo), int(hi or lo) + 1))
    return out


def table(rows: Sequence[dict[str, Any]]) -> str:
    """Markdown summary, one row per (effect, noise)."""
    lines = ["| injected | noise | named right / wrong / none | effect parameter (range) | "
             "c1 baseline → augmented (range, named) | c1 and k1 within 5 % |",
             "|---|---|---|---|---|---|"]
    keys = sorted({(r["effect_injected"], r["noise"]) for r in rows}, key=lambda k: (k[0], k[1]))
    for spec, noise in keys:
        rs = [r for r in rows if (r["effect_injected"], r["noise"]) == (spec, noise)]
        name = spec.split(":")[0]
        right = [r for r in rs if r["effect"] and r["effect"]["name"] == name]
        wrong = [r for r in rs if r["effect"] and r["effect"]["name"] != name]
        none = [r for r in rs if not r["effect"]]
        if right:
            prm = sorted(right[0]["effect"]["params"])
            rng = ", ".join(f"{k} {min(r['effect']['params'][k] for r in right):.4g}–"
                            f"{max(r['effect']['params'][k] for r in right):.4g}" for k in prm)
            c1b = [100 * r["c1_baseline"] for r in right]
            c1a = [100 * r["c1"] for r in right]
            c1 = f"{min(c1b):+.0f}…{max(c1b):+.0f} % → {min(c1a):+.1f}…{max(c1a):+.1f} %"
        else:
            rng, c1 = "—", "—"
        ok = sum(1 for r in right if abs(r["c1"]) <= 0.05 and abs(r["k1"]) <= 0.05)
        wrong_names = ", ".join(sorted({r["effect"]["name"] for r in wrong}))
        lines.append(f"| `{spec}` | {100 * noise:g} % | {len(right)} / {len(wrong)}"
                     f"{f' ({wrong_names})' if wrong else ''} / {len(none)} of {len(rs)} | {rng} | "
                     f"{c1} | {ok} of {len(rs)} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--effect", action="append",
                    help="effect spec (repeatable; default coulomb_friction:F=60 and F=150)")
    ap.add_argument("--noise", type=float, action="append",
                    help="noise fraction (repeatable; default 0.01, 0.03, 0.05)")
    ap.add_argument("--seeds", default="1-8", help="noise seeds, e.g. 1-8 or 3,7 (default 1-8)")
    ap.add_argument("--json", action="store_true", help="one JSON object per record")
    args = ap.parse_args(argv)
    rows = []
    for spec in args.effect or ["coulomb_friction:F=60", "coulomb_friction:F=150"]:
        for noise in args.noise or [0.01, 0.03, 0.05]:
            for seed in _seeds(args.seeds):
                row = run_one(spec, noise, seed)
                rows.append(row)
                if args.json:
                    print(json.dumps(row), flush=True)
    if not args.json:
        print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
