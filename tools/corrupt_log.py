#!/usr/bin/env python3
"""Damage a candump -L log: truncated lines, corrupted payloads, inserted foreign frames.

    python tools/corrupt_log.py IN.log OUT.log [--truncated 20] [--corrupted 20] [--foreign 20]

Every damaged line is one the decoder must reject (malformed/dlc, crc, unknown_id); compare
``suspid identify --input OUT.log --json`` with IN.log: ``frames.rejected`` counts them all
and the parameters stay the same within quantization.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from firmware_sim.corrupt import corrupt_candump  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("src", type=Path)
    ap.add_argument("dst", type=Path)
    ap.add_argument("--truncated", type=int, default=20)
    ap.add_argument("--corrupted", type=int, default=20)
    ap.add_argument("--foreign", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    counts = corrupt_candump(a.src, a.dst, a.truncated, a.corrupted, a.foreign, a.seed)
    print(json.dumps(counts))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
