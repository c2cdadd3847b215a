#!/usr/bin/env python3
"""Decode throughput of the estimator's CAN front end, beside classic CAN's physical limit.

Measures, best of ``--repeat`` runs (the machine may be shared; the best run is the least
disturbed one):

* ``log read``            candump -L lines -> can.Message (suspid.can.logs.read_log)
* ``log read + decode``   the same through DecodeListener (validate, CRC, counter, decode,
                          rolling buffer) -- the path of ``suspid identify --input LOG``
* ``decode only``         DecodeListener on messages already in memory
* ``cantools decode``     ``Database.decode_message`` per frame, for comparison
* ``virtual bus``         a sender thread on python-can's virtual bus, received by a
                          Notifier into DecodeListener (end to end, two threads)
* ``slcan pty``           (with ``--slcan``) the simulated adapter on a pty read by
                          python-can's ``slcan`` interface in the same process, and by
                          suspid's chunked-read ``BufferedSlcanBus``

Classic CAN at 1 Mbit/s carries at most ~9.0 k frames/s (8-byte standard frames, 111 bits
without stuff bits) and ~7.4 k frames/s with worst-case bit stuffing (135 bits).

Usage::

    python tools/bench_decode.py [--seconds 60] [--repeat 3] [--slcan] [--log PATH]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import can  # noqa: E402

from estimator.decode import DecodeListener, feed  # noqa: E402
from firmware_sim.node import NodeConfig, SensorNode  # noqa: E402
from suspid.can.dbc import load_dbc  # noqa: E402
from suspid.can.logs import open_log_writer, read_log  # noqa: E402

CAN_MAX_NO_STUFF = 1e6 / 111   # frames/s, 8-byte standard data frames at 1 Mbit/s
CAN_MAX_WORST = 1e6 / 135


def make_log(path: Path, seconds: float) -> int:
    """Record the node (quarter2, random road, 1 kHz, noise) to a candump log."""
    node = SensorNode(NodeConfig(scenario="random", duration=seconds, rate=1000.0))
    n = 0
    with open_log_writer(path) as w:
        for msg in node.frames():
            w.on_message_received(msg)
            n += 1
    return n


def best(fn, repeat: int) -> tuple[float, int]:
    """Best (frames/s, frames) of ``repeat`` runs of ``fn() -> frames``."""
    rates = []
    n = 0
    for _ in range(repeat):
        t0 = time.perf_counter()
        n = fn()
        rates.append(n / (time.perf_counter() - t0))
    return max(rates), n


def bench_virtual(msgs: list[can.Message], db) -> int:
    lst = DecodeListener("quarter2", db, capacity=1 << 20, time_source="tick")
    with can.Bus(interface="virtual", channel="bench-decode", preserve_timestamps=True) as tx, \
            can.Bus(interface="virtual", channel="bench-decode") as rx:
        notifier = can.Notifier(rx, [lst], timeout=0.01)
        for m in msgs:
            tx.send(m)
        deadline = time.monotonic() + 120
        while lst.frames < len(msgs) and time.monotonic() < deadline:
            time.sleep(0.001)
        notifier.stop()
    return lst.frames


def bench_slcan(msgs: list[can.Message], db, buffered: bool) -> int:
    from firmware_sim.transport import BufferedSlcanBus, SlcanPtyBus

    node = SlcanPtyBus(write_timeout=10.0)
    lst = DecodeListener("quarter2", db, capacity=1 << 20, time_source="tick")
    host = (BufferedSlcanBus(channel=node.path, sleep_after_open=0) if buffered
            else can.Bus(interface="slcan", channel=node.path, sleep_after_open=0))
    node.wait_open(5)
    notifier = can.Notifier(host, [lst], timeout=0.01)
    sender = threading.Thread(target=lambda: [node.send(m) for m in msgs])
    sender.start()
    sender.join()
    deadline = time.monotonic() + 120
    while lst.frames < len(msgs) and time.monotonic() < deadline:
        time.sleep(0.001)
    notifier.stop()
    host.shutdown()
    node.shutdown()
    return lst.frames


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0,
                    help="seconds of 1 kHz quarter-car data to generate (default 60: ~240 k frames)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per measurement (best kept)")
    ap.add_argument("--log", type=Path, help="decode this candump log instead (suspid DBC)")
    ap.add_argument("--slcan", action="store_true", help="also measure the SLCAN pty link")
    args = ap.parse_args()
    db = load_dbc()
    with tempfile.TemporaryDirectory() as tmp:
        log = args.log or Path(tmp) / "bench.log"
        if args.log is None:
            n = make_log(log, args.seconds)
            print(f"generated {log.name}: {n} frames ({args.seconds:g} s of quarter2 at 1 kHz)")
        msgs = list(read_log(log))
        rows = []
        rate, n = best(lambda: sum(1 for _ in read_log(log)), args.repeat)
        rows.append(("log read (candump -L)", rate, n))
        rate, n = best(lambda: feed(DecodeListener("quarter2", db, growable=True), read_log(log)),
                       args.repeat)
        rows.append(("log read + decode", rate, n))
        rate, n = best(lambda: feed(DecodeListener("quarter2", db, growable=True), msgs),
                       args.repeat)
        rows.append(("decode only (in memory)", rate, n))
        sub = msgs[:20000]

        def cantools_decode() -> int:
            for m in sub:
                try:
                    db.decode_message(m.arbitration_id, m.data)
                except Exception:
                    pass
            return len(sub)

        rate, n = best(cantools_decode, args.repeat)
        rows.append(("cantools decode_message", rate, n))
        vsub = msgs[:100000]
        rate, n = best(lambda: bench_virtual(vsub, db), args.repeat)
        rows.append(("virtual bus + Notifier + decode", rate, n))
        if args.slcan:
            ssub = msgs[:10000]
            rate, n = best(lambda: bench_slcan(ssub, db, False), 1)
            rows.append(("SLCAN pty + python-can slcan", rate, n))
            rate, n = best(lambda: bench_slcan(ssub, db, True), 1)
            rows.append(("SLCAN pty + BufferedSlcanBus", rate, n))
    print(f"\n{'path':36s} {'frames/s':>12s} {'x CAN max':>10s} {'frames':>9s}")
    for name, rate, n in rows:
        print(f"{name:36s} {rate:12,.0f} {rate / CAN_MAX_NO_STUFF:10.1f} {n:9d}")
    print(f"{'classic CAN, 1 Mbit/s, 8-byte frames':36s} {CAN_MAX_WORST:6,.0f}-{CAN_MAX_NO_STUFF:,.0f}"
          "   (worst-case stuffing - no stuffing)")
    target = dict((r[0], r[1]) for r in rows)["log read + decode"]
    print(f"\ntarget >= 100,000 frames/s from a log: {'met' if target >= 1e5 else 'NOT met'} "
          f"({target:,.0f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
