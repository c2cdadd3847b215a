"""The main job's demo (see README): simulate, identify, report, plot."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path


def suspid(*args: str) -> str:
    r = subprocess.run([sys.executable, "-m", "suspid", *args], capture_output=True, text=True)
    if r.returncode != 0:
        sys.stderr.write(r.stderr)
        raise SystemExit(r.returncode)
    return r.stdout


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    truth = dict(m1=275, c1=1120, k1=150000, m2=27, c2=3100, k2=310000)
    csv = out / "bump.csv"
    suspid("simulate", "--model", "quarter2", "--scenario", "bump", "--duration", "3",
           *[f"--param={k}={v}" for k, v in truth.items()], "--out", str(csv))
    res = json.loads(suspid("identify", "--model", "quarter2", "--input", str(csv), "--fix", "m1=275",
                            "--fix", "m2=27", "--init", "c1=560", "--init", "k1=75000", "--init",
                            "c2=1550", "--init", "k2=155000", "--json", "--plot", str(out / "identify.png")))
    print("quarter car over a 0.1 m x 3 m speed bump at 20 km/h, masses known, start at 0.5x truth")
    for k, v in res["params"].items():
        print(f"  {k:>3}: identified {v:12.6g}   truth {truth[k]:10.6g}   "
              f"error {100 * (v / truth[k] - 1):+.2e} %")
    print(f"plot: {out / 'identify.png'}")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/demo"))
