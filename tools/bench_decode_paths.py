#!/usr/bin/env python3
"""Frames/s of the decoder's paths, CPU time (best of ``--repeat``), one line per path.

Meant to be run under two checkouts alternately (before/after a change), each run a fresh
process, e.g.::

    python tools/bench_decode_paths.py --make /tmp/paths        # the logs, once
    for r in 1 2 3; do for d in BEFORE_DIR .; do
        (cd $d && PYTHONPATH=. python /path/to/tools/bench_decode_paths.py /tmp/paths)
    done; done

Paths: messages into :class:`~estimator.decode.DecodeListener` through
``on_message_received`` (the live path) with the default queue and with ``batch_size=64``
(a live bus polled often); ``feed_log`` (a candump log as arrays); the candump reader alone
(:func:`~suspid.can.logs.read_candump_arrays`), on regular lines and on lines with two
blanks after the time (none fits the column parser); ``read_log``'s candump messages; with
``--batches K,...`` also the log's arrays fed to the listener in batches of K frames (the
engine's fixed cost per batch: a live bus read often, the start of a monitor run).
CPU time (``time.process_time``) rather than wall time: the machine is shared.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Callable

from estimator.decode import DecodeListener, feed, feed_log
from suspid.can.dbc import load_dbc
from suspid.can.logs import ReadStats, read_candump_arrays, read_log


def best(fn: Callable[[], object], repeat: int) -> float:
    """Least CPU time (s) of ``repeat`` calls."""
    out = float("inf")
    for _ in range(repeat):
        t = time.process_time()
        fn()
        out = min(out, time.process_time() - t)
    return out


def feed_batches(lst: DecodeListener, chunks: list, k: int) -> None:
    """Every frame of ``chunks`` (FrameArrays) through ``lst.feed_arrays`` ``k`` at a time."""
    for c in chunks:
        for s in range(0, len(c), k):
            lst.feed_arrays(c, s, s + k)


def make(folder: Path, seconds: float) -> None:
    """Write ``bench.log`` (quarter2 at 1 kHz) and ``odd.log`` (two blanks after the time)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_decode import make_log   # noqa: PLC0415 - a sibling script, not a package
    folder.mkdir(parents=True, exist_ok=True)
    make_log(folder / "bench.log", seconds)
    text = (folder / "bench.log").read_text()
    (folder / "odd.log").write_text(text.replace(") can0 ", ")  can0 "))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", type=Path, help="folder of bench.log and odd.log")
    ap.add_argument("--make", action="store_true", help="write the logs into FOLDER and stop")
    ap.add_argument("--seconds", type=float, default=15.0, help="log length (s) for --make")
    ap.add_argument("--repeat", type=int, default=3, help="runs per path (best kept)")
    ap.add_argument("--batches", default="", help="batch sizes K,... of extra feed_arrays rows")
    args = ap.parse_args()
    if args.make:
        make(args.folder, args.seconds)
        return 0
    log, odd = args.folder / "bench.log", args.folder / "odd.log"
    db = load_dbc(None)
    msgs = list(read_log(log))
    n = len(msgs)
    k = args.repeat
    rows = {
        "messages -> listener (default batches)": lambda: feed(
            DecodeListener("quarter2", db, growable=True), msgs),
        "messages -> listener (batch_size=64)": lambda: feed(
            DecodeListener("quarter2", db, growable=True, batch_size=64), msgs),
        "feed_log (arrays) + decode": lambda: feed_log(
            DecodeListener("quarter2", db, growable=True), log),
        "read_candump_arrays": lambda: sum(len(f) for f in read_candump_arrays(log, ReadStats())),
        "read_candump_arrays, irregular lines": lambda: sum(
            len(f) for f in read_candump_arrays(odd, ReadStats())),
        "read_log (candump messages)": lambda: sum(1 for _ in read_log(log)),
    }
    chunks = list(read_candump_arrays(log, ReadStats()))
    for size in [int(x) for x in args.batches.split(",") if x]:
        rows[f"feed_arrays, batches of {size}"] = lambda size=size: feed_batches(
            DecodeListener("quarter2", db, growable=True), chunks, size)
    for name, fn in rows.items():
        print(f"{name:40s} {n / best(fn, k):12,.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
