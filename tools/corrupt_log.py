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
from pathlib import Path

import numpy as np

#: default foreign IDs (OBD-II request/response, a typical ECU range); none is in suspension.dbc
FOREIGN_IDS = (0x7DF, 0x7E8, 0x0C4, 0x3B3, 0x18F)


def corrupt_candump(src: str | Path, dst: str | Path, truncated: int = 0, corrupted: int = 0,
                    foreign: int = 0, seed: int = 0, skip: int = 20) -> dict[str, int]:
    """Copy a candump -L log with lines cut, payloads corrupted and foreign frames inserted."""
    lines = Path(src).read_text(encoding="ascii").splitlines()
    rng = np.random.default_rng(seed)
    candidates = np.arange(min(skip, len(lines)), len(lines))
    if truncated + corrupted > candidates.size:
        raise ValueError(f"{src}: {candidates.size} lines available, asked to damage "
                         f"{truncated + corrupted}")
    # damaged lines are kept apart (>= 5 lines) so no message loses two frames in a row
    pick = rng.choice(candidates[::5], size=truncated + corrupted, replace=False)
    trunc = set(int(i) for i in pick[:truncated])
    corr = set(int(i) for i in pick[truncated:])
    inserts = sorted(int(i) for i in rng.integers(min(skip, len(lines)), len(lines), size=foreign))
    out: list[str] = []
    ins_i = 0
    for i, line in enumerate(lines):
        while ins_i < len(inserts) and inserts[ins_i] == i:
            ts = line.split()[0]
            fid = FOREIGN_IDS[ins_i % len(FOREIGN_IDS)]
            data = bytes(rng.integers(0, 256, size=8, dtype=np.uint8)).hex().upper()
            out.append(f"{ts} can0 {fid:03X}#{data}")
            ins_i += 1
        if i in trunc:
            head, _, data = line.partition("#")
            hexpart = data.split()[0] if data else ""
            if rng.random() < 0.3 or len(hexpart) < 2:
                cut = int(rng.integers(2, max(3, line.index(")"))))  # inside the timestamp
                out.append(line[:cut])
            else:
                keep = int(rng.integers(0, len(hexpart)))  # remove >= 1 hex digit
                out.append(f"{head}#{hexpart[:keep]}")
            continue
        if i in corr:
            head, _, data = line.partition("#")
            parts = data.split(maxsplit=1)
            payload = bytearray(bytes.fromhex(parts[0]))
            bit = int(rng.integers(0, 8 * len(payload)))
            payload[bit // 8] ^= 1 << (bit % 8)
            rest = f" {parts[1]}" if len(parts) > 1 else ""
            out.append(f"{head}#{payload.hex().upper()}{rest}")
            continue
        out.append(line)
    Path(dst).write_text("\n".join(out) + "\n", encoding="ascii")
    return {"truncated": len(trunc), "corrupted": len(corr), "foreign": len(inserts),
            "lines": len(out)}


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
