"""Damage a candump -L log on purpose, each damaged line rejected by the decoder: truncated
lines (``malformed`` or ``dlc``), one flipped payload bit (``crc``), inserted foreign IDs
(``unknown_id``)."""
from __future__ import annotations

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
