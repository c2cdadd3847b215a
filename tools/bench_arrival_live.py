#!/usr/bin/env python3
"""Cost of the live slot rule, beside the nearest-cell placement it replaces.

A node stream without its SN_Sync frames (no sensor clock) and its jitter (0.3 ms Gaussian),
burst (5 periods delivered together) and delay (exponential, 2 ms mean, through a FIFO)
versions are fed frame by frame into ``DecodeListener(time_source="timestamp")``
(``on_message_received``, the live path after the bus), with ``arrival_slots`` off
(nearest grid cell) and on (:mod:`estimator.decode.rules.arrival_live`). Prints µs per
frame, best of ``--repeat`` runs (the machine may be shared), and their ratio.

Usage: ``python tools/bench_arrival_live.py [--duration S] [--repeat N]``
"""
from __future__ import annotations

import argparse
import re
import tempfile
import time
from pathlib import Path

import can
import numpy as np

from estimator.decode import DecodeListener
from suspid.cli import main as cli

PERIOD = 0.002
LINE = re.compile(r"\((\S+)\) (\S+) (\S+)")


def perturbed(src: Path, dst: Path, kind: str, seed: int = 1) -> None:
    """``src`` with its timestamps as a USB adapter or a busy bus would deliver them."""
    rows = [LINE.match(x).groups() for x in src.read_text().splitlines()]  # type: ignore[union-attr]
    t = np.array([float(r[0]) for r in rows])
    rng = np.random.default_rng(seed)
    if kind == "jitter":
        t = t + rng.normal(0.0, 3e-4, t.size)
    elif kind == "burst":
        t = (np.floor(t / (5 * PERIOD) + 1e-9) + 1) * 5 * PERIOD
    elif kind == "delay":
        t = np.maximum.accumulate(t + rng.exponential(2e-3, t.size))
    order = np.argsort(t, kind="stable")
    dst.write_text("".join(f"({t[i] + 100.0:.6f}) {rows[i][1]} {rows[i][2]}\n" for i in order))


def per_frame(msgs: list[can.Message], slots: bool, repeat: int) -> tuple[float, int]:
    """Best µs per frame and the samples the grid dropped (fell on a filled cell)."""
    best = float("inf")
    lost = 0
    for _ in range(repeat):
        lis = DecodeListener("quarter2", capacity=1 << 15, growable=True,
                             time_source="timestamp", arrival_slots=slots)
        t0 = time.perf_counter()
        for m in msgs:
            lis.on_message_received(m)
        lis.finish()
        lis.flush()
        best = min(best, time.perf_counter() - t0)
        lost = int(lis.aligned().collisions)
    return best / len(msgs) * 1e6, lost


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=8.0, help="stream length (s)")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        node = d / "node.log"
        cli(["node", "--scenario", "damper-wear", "--duration", str(args.duration),
             "--wear-start", "2", "--speed", "0", "--log", str(node)])
        clean = d / "clean.log"
        clean.write_text("".join(x + "\n" for x in node.read_text().splitlines()
                                 if " 100#" not in x))
        print(f"{'stream':8s} {'frames':>7s} {'nearest µs/frame':>17s} {'slots µs/frame':>15s} "
              f"{'ratio':>6s} {'samples dropped: nearest':>25s} {'slots':>6s}")
        for kind in ("clean", "jitter", "burst", "delay"):
            path = clean
            if kind != "clean":
                path = d / f"{kind}.log"
                perturbed(clean, path, kind)
            msgs = list(can.LogReader(str(path)))
            near, lost_n = per_frame(msgs, False, args.repeat)
            slot, lost_s = per_frame(msgs, True, args.repeat)
            print(f"{kind:8s} {len(msgs):7d} {near:17.1f} {slot:15.1f} {slot / near:6.1f} "
                  f"{lost_n:25d} {lost_s:6d}")


if __name__ == "__main__":
    run()
