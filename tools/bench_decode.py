#!/usr/bin/env python3
"""Decode throughput of the estimator's CAN front end, beside classic CAN's physical limit.

Measures, best of ``--repeat`` runs (the machine may be shared; the best run is the least
disturbed one):

* ``log read``            candump -L lines -> can.Message (suspid.can.logs.read_log)
* ``log read + decode``   the same through DecodeListener (validate, CRC, counter, decode,
                          rolling buffer) -- the path of ``suspid identify --input LOG``
* ``feed_log``            the array path of ``identify``/``diagnose``/``monitor --input LOG``
                          (estimator.decode.feed_log: candump lines parsed as columns,
                          decoded in batches), on the generated log with times from 0 and
                          on the same frames with epoch times (t0 = 1631416514 s, as real
                          candump logs have: 16-digit timestamps), and on lines the
                          column parser does not take (two blanks after the time: all of
                          them through python-can's CanutilsLogReader, merged back in file order)
* ``load_log_as_measurement``  log -> uniform-grid measurement (feed_log + alignment), on
                          the epoch-time log and on the real candump-drive log (82,558
                          frames, ../shared/realdata; skipped when absent)
* ``... user DBC``         the same on a user's DBC and map, one frame per 1 kHz sample:
                          ``plain`` the three signals in every frame, ``multiplexed`` the
                          body and wheel position on pages 0 and 1 of one message in turn
                          (plus two pages not mapped), the road in every frame
                          (:func:`make_user_logs`; frames encoded by cantools)
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
                                 [--real PATH]
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
import cantools  # noqa: E402
import numpy as np  # noqa: E402

from estimator.decode import (DecodeListener, feed, feed_log,  # noqa: E402
                              load_log_as_measurement)
from firmware_sim.node import NodeConfig, SensorNode  # noqa: E402
from suspid.can.dbc import load_dbc  # noqa: E402
from suspid.can.logs import open_log_writer, read_log, read_log_arrays  # noqa: E402

CAN_MAX_NO_STUFF = 1e6 / 111   # frames/s, 8-byte standard data frames at 1 Mbit/s
CAN_MAX_WORST = 1e6 / 135
#: an epoch time (s) of a real log (candump-drive's first frame, 2021-09-12)
EPOCH_T0 = 1631416514.0
#: the real candump log (its DBC and signal as in tests/can/test_realdata.py)
REAL_LOG = Path(__file__).resolve().parents[2] / "shared" / "realdata" / "candump-drive" / \
    "can_sample.log"


def make_log(path: Path, seconds: float) -> int:
    """Record the node (quarter2, random road, 1 kHz, noise) to a candump log."""
    node = SensorNode(NodeConfig(scenario="random", duration=seconds, rate=1000.0))
    n = 0
    with open_log_writer(path) as w:
        for msg in node.frames():
            w.on_message_received(msg)
            n += 1
    return n


#: a user's DBC: a multiplexed message (pages 0-3) and the same signals in a plain one
USER_DBC = """VERSION ""

NS_ :

BS_:

BU_: ECU

BO_ 512 Chassis: 8 ECU
 SG_ Page M : 0|8@1+ (1,0) [0|255] "" ECU
 SG_ Height m0 : 8|16@1- (1e-05,0) [-0.32768|0.32767] "m" ECU
 SG_ Wheel m1 : 8|16@1- (1e-05,0) [-0.32768|0.32767] "m" ECU
 SG_ Temp m2 : 8|16@1- (0.1,-40) [-40|200] "degC" ECU
 SG_ Volt m3 : 8|16@1- (0.001,0) [0|65] "V" ECU
 SG_ Road : 39|16@0- (1e-05,0) [-0.32768|0.32767] "m" ECU

BO_ 513 Plain: 8 ECU
 SG_ Height : 8|16@1- (1e-05,0) [-0.32768|0.32767] "m" ECU
 SG_ Wheel : 24|16@1- (1e-05,0) [-0.32768|0.32767] "m" ECU
 SG_ Road : 55|16@0- (1e-05,0) [-0.32768|0.32767] "m" ECU
"""
USER_MAPS = {"plain": ["x1=Plain.Height", "x2=Plain.Wheel", "r=Plain.Road"],
             "multiplexed": ["x1=Chassis.Height", "x2=Chassis.Wheel", "r=Chassis.Road"]}


def make_user_logs(tmp: Path, seconds: float) -> tuple[Path, dict[str, Path]]:
    """The DBC :data:`USER_DBC` and two candump logs of one frame per 1 kHz sample (epoch
    times): ``plain`` and ``multiplexed`` (pages 0, 1, 2, 3 in turn)."""
    dbc = tmp / "user.dbc"
    dbc.write_text(USER_DBC)
    db = cantools.database.load_file(str(dbc))
    mux, plain = db.get_message_by_name("Chassis"), db.get_message_by_name("Plain")
    n = int(round(seconds * 1000))
    t = EPOCH_T0 + np.arange(n) * 1e-3
    x = np.round(0.01 * np.sin(2 * np.pi * 1.3 * (t - EPOCH_T0)), 5)
    logs = {"plain": tmp / "user_plain.log", "multiplexed": tmp / "user_mux.log"}
    with open_log_writer(logs["plain"]) as w:
        for i in range(n):
            w.on_message_received(can.Message(
                timestamp=t[i], arbitration_id=plain.frame_id, is_extended_id=False,
                data=plain.encode({"Height": x[i], "Wheel": x[i] / 2, "Road": x[i] / 4})))
    with open_log_writer(logs["multiplexed"]) as w:
        for i in range(n):
            page = i % 4
            sig = [{"Height": x[i]}, {"Wheel": x[i] / 2}, {"Temp": 25.0}, {"Volt": 12.0}][page]
            w.on_message_received(can.Message(
                timestamp=t[i], arbitration_id=mux.frame_id, is_extended_id=False,
                data=mux.encode({"Page": page, "Road": x[i] / 4, **sig})))
    return dbc, logs


def shifted_copy(msgs: list[can.Message], path: Path, t0: float) -> None:
    """Write ``msgs`` to a candump log with ``t0`` added to every timestamp."""
    with open_log_writer(path) as w:
        for m in msgs:
            ts = m.timestamp
            m.timestamp = ts + t0
            w.on_message_received(m)
            m.timestamp = ts


def log_frames(path: Path) -> int:
    return sum(len(fa) for fa in read_log_arrays(path))


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
    ap.add_argument("--real", type=Path, default=REAL_LOG,
                    help="the real candump-drive log (default ../shared/realdata/...)")
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
        rate, n = best(lambda: feed_log(DecodeListener("quarter2", db, growable=True), log),
                       args.repeat)
        rows.append(("feed_log (arrays) + decode, t from 0", rate, n))
        epoch_log = Path(tmp) / "bench_epoch.log"
        shifted_copy(msgs, epoch_log, EPOCH_T0)
        rate, n = best(lambda: feed_log(DecodeListener("quarter2", db, growable=True),
                                        epoch_log), args.repeat)
        rows.append(("feed_log (arrays) + decode, epoch t", rate, n))
        odd_log = Path(tmp) / "bench_spaced.log"   # two blanks: every line off the columns
        odd_log.write_text(epoch_log.read_text().replace(") can0 ", ")  can0 "))
        rate, n = best(lambda: feed_log(DecodeListener("quarter2", db, growable=True),
                                        odd_log), args.repeat)
        rows.append(("feed_log, irregular lines (line by line)", rate, n))
        n_epoch = log_frames(epoch_log)
        rate, n = best(lambda: (load_log_as_measurement(epoch_log, "quarter2"), n_epoch)[1],
                       args.repeat)
        rows.append(("load_log_as_measurement, epoch t", rate, n))
        if args.real.is_file():
            real_dbc = args.real.with_name("sample_can_spec.dbc")
            n_real = log_frames(args.real)
            rate, n = best(lambda: (load_log_as_measurement(
                args.real, "quarter1", real_dbc, ["x_ddot=ID_D0.ACCEL_LONG"]), n_real)[1],
                args.repeat)
            rows.append(("load_log_as_measurement, candump-drive", rate, n))
        else:
            print(f"(real log {args.real} not found: its row is skipped)")
        user_dbc, user_logs = make_user_logs(Path(tmp), args.seconds)
        for kind, path in user_logs.items():
            n_user = log_frames(path)
            rate, n = best(lambda p=path, k=kind, m=n_user: (load_log_as_measurement(
                p, "quarter2", user_dbc, USER_MAPS[k]), m)[1], args.repeat)
            rows.append((f"load_log_as_measurement, {kind} user DBC", rate, n))
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
    print(f"\n{'path':46s} {'frames/s':>12s} {'x CAN max':>10s} {'frames':>9s}")
    for name, rate, n in rows:
        print(f"{name:46s} {rate:12,.0f} {rate / CAN_MAX_NO_STUFF:10.1f} {n:9d}")
    print(f"{'classic CAN, 1 Mbit/s, 8-byte frames':46s} {CAN_MAX_WORST:6,.0f}-"
          f"{CAN_MAX_NO_STUFF:,.0f}   (worst-case stuffing - no stuffing)")
    rate_of = dict((r[0], r[1]) for r in rows)
    print()
    for name in ("log read + decode", "feed_log (arrays) + decode, epoch t",
                 "load_log_as_measurement, candump-drive"):
        if name in rate_of:
            target = rate_of[name]
            print(f"target >= 100,000 frames/s from a log ({name}): "
                  f"{'met' if target >= 1e5 else 'NOT met'} ({target:,.0f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
