"""Bus faults: the decoder keeps running, counts and marks every gap; estimates degrade gracefully.

Also the bounded-memory checks: a long candump log streamed through a bounded listener.
"""
from __future__ import annotations

import math
import re
import threading
import time
import tracemalloc
from pathlib import Path
from typing import Any

import can
import numpy as np
import pytest

from estimator.decode import DecodeListener, feed
from estimator.decode.log_input import load_log_as_measurement
from estimator.stream.drivers import (RECEIVE_RATE, CanWindowDriver, LiveStop, LossLedger,
                                      receive_capacity, run_bus)
from firmware_sim.faults import FaultConfig
from firmware_sim.node import NodeConfig, SensorNode
from suspid.can.bus import error_frame_classes, open_bus
from suspid.can.crc import e2e_protect
from suspid.can.dbc import load_dbc
from suspid.can.logs import FrameArrays, ReadStats, read_log
from tools.fault_table import run_condition

CH = ["x1", "x2", "r"]


def _node_frames(faults: tuple[str, ...] = (), duration: float = 2.0, seed: int = 0,
                 t_shift: float = 0.0) -> tuple[list[can.Message], SensorNode]:
    cfg = NodeConfig(model="quarter2", scenario="bump", duration=duration, speed=0.0,
                     channels=list(CH), seed=seed, faults=FaultConfig.parse(faults, CH))
    node = SensorNode(cfg)
    frames = list(node.frames())
    for m in frames:
        m.timestamp += t_shift
    return frames, node


def _data_frames(frames: list[can.Message]) -> int:
    return sum(1 for m in frames if m.arbitration_id in (0x110, 0x111, 0x112))


@pytest.mark.parametrize("faults", [("loss=0.01",), ("loss=0.05",), ("loss=0.10",),
                                    ("burst=2:0.02",), ("burst=1:0.1",), ("busoff=0.7:0.3",)])
def test_loss_is_counted_and_marked_as_gaps(faults: tuple[str, ...]) -> None:
    clean, _ = _node_frames()
    lossy, node = _node_frames(faults)
    lst = DecodeListener("quarter2", node.db)
    feed(lst, lossy)
    st = lst.frame_stats()
    assert sum(st["rejected"].values()) == 0 and st["accepted"] == len(lossy)
    dropped = len(clean) - len(lossy)
    assert dropped > 0
    # every dropped frame (bar the ones after the last received frame of an ID) is counted
    assert dropped - 8 <= st["lost"] <= dropped
    al = lst.aligned()
    missing = sum(int(np.isnan(al.values[c]).sum()) for c in CH)
    dd = _data_frames(clean) - _data_frames(lossy)
    # every lost data frame is a NaN grid cell (a loss after the last frame only shortens it)
    assert dd - 6 <= missing <= dd
    assert any(g.channel == "x1" for g in al.gaps)


def test_node_restart_counter_reset_resynchronises() -> None:
    """A node reboot: counters restart from 0 while time goes on; one frame per ID at most lost."""
    a, node = _node_frames(duration=1.0)
    b, _ = _node_frames(duration=1.0, seed=1, t_shift=1.5 + 0.002 * 7)  # tick 0 again
    lst = DecodeListener("quarter2", node.db)
    feed(lst, a + b)
    st = lst.frame_stats()
    rejected = sum(st["rejected"].values())
    assert st["accepted"] + rejected == len(a) + len(b)
    assert rejected <= 5  # one resynchronising frame per message ID at most
    al = lst.aligned()
    gap = [g for g in al.gaps if g.channel == "x1"]
    assert gap and max(g.t_end - g.t_start for g in gap) >= 0.4  # the reboot pause is a gap


def _tick_offset(frames: list[can.Message], offset: int) -> list[can.Message]:
    """The node's frames as a node whose Tick started at ``offset`` would send them (mod 2^32):
    SN_Sync's Tick and every E2E counter (Tick mod 15) rewritten, CRC recomputed."""
    out, tick = [], None
    for m in frames:
        d = bytearray(m.data)
        if m.arbitration_id == 0x100:
            tick = (int.from_bytes(d[2:6], "little") + offset) % (1 << 32)
            d[2:6] = tick.to_bytes(4, "little")
        if m.arbitration_id in (0x100, 0x110, 0x111, 0x112) and tick is not None:
            e2e_protect(d, m.arbitration_id, tick % 15)
        out.append(can.Message(timestamp=m.timestamp, arbitration_id=m.arbitration_id,
                               is_extended_id=False, data=d))
    return out


def _fed_both_ways(frames: list[can.Message], db: object) -> list[DecodeListener]:
    """The frames through one listener frame by frame and another as one array batch."""
    one = DecodeListener("quarter2", db, time_source="tick")
    feed(one, frames)
    batch = DecodeListener("quarter2", db, time_source="tick")
    batch.feed_arrays(FrameArrays.from_messages(frames))
    batch.finish()
    return [one, batch]


def test_node_restart_mid_drive_continues_the_data_time() -> None:
    """A node restart after 1.5 s of driving (Tick back to 0 after a 0.3 s pause): the samples
    after it follow the ones before after a gap of the pause (were: placed at 0..1 s again,
    in the past of the stream, so no window after the restart was ever cut)."""
    a, node = _node_frames(duration=1.5)
    b, _ = _node_frames(duration=1.0, seed=1, t_shift=1.8)
    for lst in _fed_both_ways(a + b, node.db):
        assert lst.engine.clock.restarts == 1 and lst.frame_stats()["node_restarts"] == 1
        t, _ = lst.buffer.series("x1")
        assert np.all(np.diff(t) > 0)
        assert t[-1] == pytest.approx(2.8, abs=0.01)   # 1.5 s + pause 0.3 s + 1.0 s
        gap = max(g.t_end - g.t_start for g in lst.aligned().gaps if g.channel == "x1")
        assert gap == pytest.approx(0.3, abs=0.01)


def test_sensor_tick_wrap_keeps_the_data_time_exact() -> None:
    """SN_Sync's 32-bit Tick wraps 1 s into the log (99 days at 500 Hz): data time goes on
    at the period (was: back by 8.6e6 s, every later sample in the past of the stream);
    the sample at the wrap repeats the counter and is lost."""
    a, node = _node_frames(duration=2.0)
    frames = _tick_offset(a, (1 << 32) - 500)
    for lst in _fed_both_ways(frames, node.db):
        assert lst.engine.clock.wraps == 1 and lst.frame_stats()["tick_wraps"] == 1
        t, _ = lst.buffer.series("x1")
        t = t - ((1 << 32) - 500) * 0.002
        assert np.all(np.diff(t) > 0)
        assert t[0] == pytest.approx(0.0, abs=1e-6) and t[-1] == pytest.approx(2.0, abs=1e-6)
        assert t.size >= 1000   # one sample at most lost at the wrap
        assert sum(lst.frame_stats()["rejected"].values()) <= 4


def test_clock_jump_back_reanchors_and_forward_jump_is_a_gap() -> None:
    a, node = _node_frames(duration=1.0)
    b, _ = _node_frames(duration=1.0, seed=2)  # the logger clock reset to 0 (back by 1 s)
    lst = DecodeListener("quarter2", node.db)
    feed(lst, a + b)
    st = lst.frame_stats()
    assert lst.time_resyncs == 1
    assert 0 < st["rejected"]["time"] <= 15
    assert st["accepted"] + sum(st["rejected"].values()) == len(a) + len(b)
    # forward jump by 20 s: accepted, the hole is one gap per channel
    c, _ = _node_frames(duration=1.0, seed=3, t_shift=21.0)
    lst = DecodeListener("quarter2", node.db)
    feed(lst, a + c)
    al = lst.aligned()
    assert sum(lst.frame_stats()["rejected"].values()) <= 5
    longest = max(g.samples for g in al.gaps if g.channel == "x1")
    assert longest == pytest.approx(20.0 * 500, rel=0.01)


@pytest.mark.slow
def test_identification_degrades_gracefully_with_loss() -> None:
    """Fast version of tools/fault_table.py: error stays small as loss grows."""
    errs = {}
    for label, faults in [("none", ()), ("5 %", ("loss=0.05",)), ("10 %", ("loss=0.10",)),
                          ("bursts", ("burst=1:0.1",))]:
        r = run_condition(faults, scenario="bump", duration=3.0, seed=0, maxfev=1500,
                          restarts=1)
        errs[label] = max(r["errors"].values())
    assert errs["none"] < 0.01
    assert errs["5 %"] < 0.03 and errs["10 %"] < 0.05 and errs["bursts"] < 0.10, errs


# ---- bounded memory ----------------------------------------------------------------------
def _write_candump(path: Path, n_samples: int) -> int:
    """A candump log of ``n_samples`` samples: a 990-sample node block repeated (990 = 66
    counter cycles, so counters and time run on seamlessly)."""
    frames, _ = _node_frames(duration=2.0)
    per = 990
    one = [m for m in frames if m.arbitration_id != 0x310 and m.timestamp < per * 0.002 - 1e-9]
    with path.open("w") as fh:
        for rep in range(n_samples // per):
            off = rep * per * 0.002
            fh.writelines(f"({m.timestamp + off:.6f}) can0 {m.arbitration_id:03X}#"
                          f"{m.data.hex().upper()}\n" for m in one)
    return (n_samples // per) * len(one)


def _peak_stream(path: Path) -> tuple[int, DecodeListener]:
    lst = DecodeListener("quarter2", capacity=4096)
    stats = ReadStats()
    tracemalloc.start()
    try:
        feed(lst, read_log(path, stats))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return peak, lst


@pytest.mark.slow
def test_long_log_streams_in_bounded_memory(tmp_path: Path) -> None:
    """Peak traced memory of streaming a log does not grow with its length (4x frames)."""
    short, long_ = tmp_path / "short.log", tmp_path / "long.log"
    n_short = _write_candump(short, 4_950)
    n_long = _write_candump(long_, 19_800)
    peak_s, _ = _peak_stream(short)
    peak_l, lst = _peak_stream(long_)
    assert lst.frame_stats()["accepted"] == n_long and n_long == 4 * n_short
    assert lst.buffer.overwritten > 0          # the ring wrapped: memory is bounded by capacity
    assert peak_l < 1.3 * peak_s + 256_000, (peak_s, peak_l)
    # the listener's rings: 3 data messages x 4096 rows x (1 + 2 or 3 columns) doubles
    assert peak_l < 2_000_000


def _peak_load(path: Path) -> tuple[int, Any, dict[str, Any]]:
    tracemalloc.start()
    try:
        # the repeated block repeats its SN_Sync ticks too: its time is the timestamps'
        meas, frames = load_log_as_measurement(path, "quarter2", time_source="timestamp")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return peak, meas, frames


def test_whole_log_loading_memory_is_linear_and_compact(tmp_path: Path) -> None:
    """Offline loading keeps a few doubles per value plus the aligned grid, not per-frame
    objects: each further sample (4 frames) costs under 6 grid rows of 9 doubles (measured
    ~350 B: the growable rings, at most doubled, and the grid; a Python object per frame
    would cost several hundred bytes per frame), on top of a fixed share (one 512 kB chunk
    of text parsed, the rings' first 16 k rows)."""
    n = {}
    peak = {}
    for k in (19_800, 39_600):
        p = tmp_path / f"big{k}.log"
        n[k] = _write_candump(p, k)
        peak[k], meas, frames = _peak_load(p)
        assert frames["accepted"] == n[k] and meas.t.size == k
    row = 8 * 9                                    # grid: 9 columns of doubles per sample
    per_sample = (peak[39_600] - peak[19_800]) / 19_800
    assert per_sample < 6 * row, (per_sample, peak)
    assert peak[19_800] < 19_800 * row * 8, peak


# ---- live reception: lost frames by cause ------------------------------------------------
def _without(frames: list[can.Message], drop: set[int]) -> list[can.Message]:
    return [m for i, m in enumerate(frames) if i not in drop]


def _sample_starts(frames: list[can.Message]) -> list[int]:
    """Indices of the SN_Sync frames (each sample's first frame)."""
    return [i for i, m in enumerate(frames) if m.arbitration_id == 0x100]


def test_loss_ledger_books_counter_gaps_to_the_loss_they_follow() -> None:
    """A gap found at a message's first frame after a loss event is that loss's; a gap
    elsewhere is nobody's (``none``): each lost frame is counted once."""
    frames, node = _node_frames(duration=1.0)
    starts = _sample_starts(frames)
    # one whole sample lost just before the event (4 E2E frames; none is an SN_Status)
    a, b = starts[201], starts[202]
    assert all(m.arbitration_id in (0x100, 0x110, 0x111, 0x112) for m in frames[a:b])
    # and one QC_Body frame lost 100 samples later, with no event
    late = next(i for i in range(starts[300], starts[301]) if frames[i].arbitration_id == 0x110)
    kept = _without(frames, set(range(a, b)) | {late})
    cut = a                                   # the event sits where the sample went missing
    lst = DecodeListener("quarter2", node.db)
    drv = CanWindowDriver(lst, 0.5, 0.25, lambda t, d: None)
    ledger = LossLedger(lst)
    ledger.feed(kept[:cut], drv.on_message)
    ledger.event("socket_overrun", kept[cut].timestamp)
    ledger.feed(kept[cut:], drv.on_message)
    drv.flush()
    assert lst.counts.lost == 5
    assert ledger.summary(lst.counts.lost) == {"socket_overrun": 4, "bus": 0,
                                               "buffer_overflow": 0, "none": 1}


def test_loss_ledger_watch_ends_after_each_message_delivered() -> None:
    """An event with nothing lost books nothing, and a later gap of the same message is not
    the event's (the watch ended at that message's first frame after it)."""
    frames, node = _node_frames(duration=1.0)
    starts = _sample_starts(frames)
    late = next(i for i in range(starts[203], starts[204]) if frames[i].arbitration_id == 0x111)
    kept = _without(frames, {late})
    lst = DecodeListener("quarter2", node.db)
    drv = CanWindowDriver(lst, 0.5, 0.25, lambda t, d: None)
    ledger = LossLedger(lst)
    ledger.feed(kept[:starts[200]], drv.on_message)
    ledger.event("bus", kept[starts[200]].timestamp)
    ledger.feed(kept[starts[200]:], drv.on_message)
    assert lst.counts.lost == 1
    assert ledger.summary(lst.counts.lost) == {"socket_overrun": 0, "bus": 0,
                                               "buffer_overflow": 0, "none": 1}


@pytest.mark.realtime
def test_live_receiver_counts_error_frames_apart_and_overrun_unknown_off_socketcan() -> None:
    """A virtual bus: error frames are counted (not decoded), counter gaps are ``none``'s,
    and the socket overrun is unknown (``None``), not 0."""
    frames, node = _node_frames(duration=2.0)
    starts = _sample_starts(frames)
    drop = {i for k in (100, 400, 700) for i in range(starts[k], starts[k] + 4)
            if frames[i].arbitration_id == 0x110}
    sent = _without(frames, drop)
    err = can.Message(arbitration_id=0x004, is_error_frame=True, data=bytes([0, 0x01, 0, 0, 0, 0, 0, 0]),
                      timestamp=sent[500].timestamp)
    assert error_frame_classes(err) == ["controller", "rx_overflow"]
    sent.insert(500, err)
    chan = f"faults-{time.monotonic_ns()}"
    rx = open_bus("virtual", chan)
    tx = can.Bus(interface="virtual", channel=chan, preserve_timestamps=True)
    lst = DecodeListener("quarter2", node.db)
    drv = CanWindowDriver(lst, 0.5, 0.25, lambda t, d: None)
    stop = LiveStop(idle_timeout=1.0)

    def send() -> None:
        for m in sent:
            tx.send(m)

    th = threading.Thread(target=send)
    th.start()
    try:
        n = run_bus(drv, rx, stop)
    finally:
        th.join()
        tx.shutdown()
        rx.shutdown()
    f = lst.frame_stats()
    r = f["receive"]
    assert n == len(sent) - 1 and r["read"] == len(sent)
    assert r["error_frames"] == 1 and f["rejected"]["frame_type"] == 0
    assert f["accepted"] == len(sent) - 1
    assert r["socket_overrun"] is None and "bus_errors" not in r
    assert r["counter_gap"] == len(drop) == 3
    assert r["counter_gap_after"] == {"socket_overrun": 0, "bus": 0, "buffer_overflow": 0,
                                      "none": 3}
    assert r["lost_by_cause"] == {"buffer_overflow": 0, "socket_overrun": None, "bus": 0,
                                  "counter_gap": 3}


def test_receive_buffer_is_sized_in_seconds_of_the_dbc_frame_rate() -> None:
    """Every DBC message with a cycle time at that rate (read here from the DBC's text),
    at least a saturated 1 Mbit/s bus."""
    db = load_dbc()
    text = (Path(__file__).resolve().parents[2] / "suspid" / "data" / "suspension.dbc").read_text()
    cycles = [int(x) for x in re.findall(r'BA_ "GenMsgCycleTime" BO_ \d+ (\d+);', text)]
    rate = sum(1000.0 / c for c in cycles if c)
    assert rate > RECEIVE_RATE
    assert receive_capacity(10.0, db) == math.ceil(10.0 * rate)
    assert receive_capacity(2.5, None) == math.ceil(2.5 * RECEIVE_RATE)


@pytest.mark.realtime
def test_live_receiver_buffer_overflow_gaps_are_not_counted_again() -> None:
    """A receiver buffer of a hundred frames and a first fit that stalls for 0.3 s while
    the frames keep coming: frames are dropped at the full buffer (``buffer_overflow``),
    and the counter gaps they leave are booked to that loss
    (``counter_gap_after.buffer_overflow``), none to ``none``."""
    frames, node = _node_frames(duration=3.0)
    chan = f"overflow-{time.monotonic_ns()}"
    rx = open_bus("virtual", chan)
    tx = can.Bus(interface="virtual", channel=chan, preserve_timestamps=True)
    slept = threading.Event()

    def slow_first_fit(t: object, d: object) -> None:
        if not slept.is_set():
            time.sleep(0.3)
            slept.set()

    lst = DecodeListener("quarter2", node.db)
    drv = CanWindowDriver(lst, 0.5, 0.25, slow_first_fit)

    def send() -> None:
        for k, m in enumerate(frames):      # about 4 k frames/s: the decoder keeps up
            tx.send(m)
            if k % 20 == 19:
                time.sleep(0.005)

    th = threading.Thread(target=send)
    th.start()
    try:
        n = run_bus(drv, rx, LiveStop(idle_timeout=1.0), buffer_s=0.01)
    finally:
        th.join()
        tx.shutdown()
        rx.shutdown()
    r = lst.frame_stats()["receive"]
    rate = sum(1000.0 / m.cycle_time for m in node.db.messages if m.cycle_time)
    cap = math.ceil(0.01 * rate)
    assert r["buffer_capacity"] == cap and r["max_queued"] <= cap
    assert r["buffer_overflow"] > 0 and n + r["buffer_overflow"] == len(frames) == r["read"]
    after = r["counter_gap_after"]
    assert 0 < after["buffer_overflow"] <= r["buffer_overflow"]
    assert after["none"] == 0 and after["socket_overrun"] == after["bus"] == 0, r
    assert r["lost_by_cause"] == {"buffer_overflow": r["buffer_overflow"], "socket_overrun": None,
                                  "bus": 0, "counter_gap": 0}
