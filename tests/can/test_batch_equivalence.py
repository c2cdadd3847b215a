"""The decoder's batch path applies the rules exactly as the frame-by-frame oracle does.

:class:`estimator.decode.DecodeListener` validates and decodes queued frames in batches of any
size with NumPy (``on_message_received`` + implicit flush, ``feed_arrays``);
:mod:`tests.can.frame_by_frame` applies the same rules one frame at a time. Property: whatever the
stream -- valid node output with drops, bursts, bit flips, duplicates, reordering, foreign
and unknown IDs, wrong DLCs, error/remote/FD frames, clocks going back, NaN/inf times, node
restarts (counter resets), silences, corrupted alerts -- and wherever the batches are cut,
the results are identical to the oracle's on the same frames one by one:
every counter by reason, lost frames, per-message acceptance and state, SN_Sync/SN_Status
and alert state, and the rolling buffers bit for bit (times, values including NaN, write
index, fill, capacity, overwritten rows), in both time sources.
"""
from __future__ import annotations

import math
from pathlib import Path

import can
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from estimator.decode import DecodeListener, feed_log
from tests.can.frame_by_frame import frame_by_frame
from firmware_sim.node import NodeConfig, SensorNode
from firmware_sim.faults import FaultConfig
from suspid.can.codec import SensorEncoder, encode_alert, encode_status, make_message
from suspid.can.crc import e2e_protect
from suspid.can.dbc import load_dbc
from suspid.can.logs import FrameArrays, ReadStats, read_log

DB = load_dbc()
FS = 500.0
_SETTINGS = settings(max_examples=60, deadline=None,
                     suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def snapshot(lst: DecodeListener) -> dict[str, object]:
    """Everything observable of a listener, buffers as raw bytes (NaN payloads included)."""
    out: dict[str, object] = {"stats": lst.frame_stats(), "per_message": lst.per_message(),
                              "state": lst.state(), "status": dict(lst.node_status),
                              "alerts": [dict(a) for a in lst.alerts], "frames": lst.frames,
                              "resyncs": lst.time_resyncs, "period": lst.period,
                              "overwritten": lst.buffer.overwritten}
    for name, src in lst.buffer.sources.items():
        t, v = src.snapshot()
        out[name] = (t.tobytes(), v.tobytes(), src.w, src.n, src.cap, src.overwritten,
                     np.frombuffer(src.t, dtype=np.float64).tobytes())
    return out


def feed_in_chunks(lst: DecodeListener, fa: FrameArrays, chunks: list[int]) -> None:
    """Feed every row of ``fa`` in chunks of the given sizes, cycling through them."""
    pos = k = 0
    while pos < len(fa):
        step = chunks[k % len(chunks)]
        lst.feed_arrays(fa, pos, pos + step)
        pos += step
        k += 1


def _node_stream(rng: np.random.Generator, n: int, channels: list[str], tick0: int = 0,
                 t0: float = 0.0, status_every: int = 50) -> list[can.Message]:
    """Valid quarter-car node output: SN_Sync + sensor frames per sample, SN_Status."""
    enc = SensorEncoder(DB, "quarter2", channels)
    out = []
    scount = 0
    for k in range(n):
        t = t0 + k / FS
        fid, data = enc.sync_frame(tick0 + k, 1 / FS)
        out.append(make_message(fid, data, t))
        vals = {c: float(rng.normal(0.0, 0.02)) if rng.random() > 0.02 else math.nan
                for c in channels}
        if rng.random() < 0.01:
            vals[channels[0]] = 50.0   # saturated: Valid = 0
        for fid, data in enc.sample_frames(tick0 + k, vals):
            out.append(make_message(fid, data, t))
        if status_every and k % status_every == 0:
            fid, data = encode_status(DB, scount, 1, FS, 0, 0, 1)
            scount += 1
            out.append(make_message(fid, data, t))
    return out


def _corrupt(rng: np.random.Generator, frames: list[can.Message], rates: dict[str, float],
             tick_mode: bool) -> list[can.Message]:
    """Apply the faults of a bus and a logger to a valid stream."""
    out: list[can.Message] = []
    i = 0
    n = len(frames)
    while i < n:
        m = frames[i]
        u = rng.random()
        if u < rates["drop"]:
            i += 1
            continue
        if rng.random() < rates["burst"]:
            i += int(rng.integers(2, 80))        # a burst loss / bus-off: many frames gone
            continue
        m = can.Message(timestamp=m.timestamp, arbitration_id=m.arbitration_id,
                        is_extended_id=m.is_extended_id, data=bytearray(m.data), check=False)
        if rng.random() < rates["flip"]:
            bit = int(rng.integers(0, 8 * len(m.data)))
            m.data[bit // 8] ^= 1 << (bit % 8)
        if rng.random() < rates["dlc"]:
            m.data = m.data[:int(rng.integers(0, len(m.data)))] if rng.random() < 0.7 \
                else m.data + bytearray(rng.integers(0, 256, int(rng.integers(1, 3))).tolist())
        if rng.random() < rates["time"]:
            kind = rng.integers(0, 5)
            if kind == 0:
                m.timestamp -= float(rng.uniform(0.001, 0.2))      # a late timestamp
            elif kind == 1:
                m.timestamp = [math.nan, math.inf, -math.inf][int(rng.integers(0, 3))]
            elif kind == 2:
                m.timestamp += float(rng.uniform(0.5, 3.0))        # a jump ahead
            else:
                m.timestamp -= float(rng.uniform(0.0, 1e-4))
        if rng.random() < rates["jitter"]:
            # arrival-time bunching (tick mode), a jittery logger clock (timestamps)
            m.timestamp += float(rng.uniform(0.0, 0.02 if tick_mode else 0.0015))
        out.append(m)
        if rng.random() < rates["dup"]:
            out.append(can.Message(timestamp=m.timestamp, arbitration_id=m.arbitration_id,
                                   is_extended_id=m.is_extended_id, data=bytearray(m.data),
                                   check=False))
        if rng.random() < rates["foreign"]:
            kind = rng.integers(0, 6)
            t = m.timestamp
            if kind == 0:     # unknown standard ID
                out.append(can.Message(timestamp=t, arbitration_id=int(rng.integers(0, 0x7FF)),
                                       is_extended_id=False, data=bytes(8), check=False))
            elif kind == 1:   # a DBC ID as an extended frame: foreign
                out.append(can.Message(timestamp=t, arbitration_id=0x110, is_extended_id=True,
                                       data=bytes(8), check=False))
            elif kind == 2:   # a known message that carries no mapped channel (half car)
                data = bytearray(8)
                e2e_protect(data, 0x120, int(rng.integers(0, 15)))
                out.append(make_message(0x120, data, t))
            elif kind == 3:   # error or remote frame
                out.append(can.Message(timestamp=t, is_error_frame=bool(rng.random() < 0.5),
                                       is_remote_frame=True, arbitration_id=0x110, dlc=8,
                                       check=False))
            elif kind == 4:   # CAN FD payload under a DBC ID
                out.append(can.Message(timestamp=t, arbitration_id=0x110, is_fd=True,
                                       is_extended_id=False,
                                       data=bytes(rng.integers(0, 256, 12).tolist()),
                                       check=False))
            else:             # an alert frame (valid, or CRC-valid with a bad ParamKind)
                a = encode_alert(DB, "quarter2", "c1", 900.0, 1500.0, "warning",
                                 int(rng.integers(0, 15)))
                a.timestamp = t
                if rng.random() < 0.3:
                    a.data = bytearray(a.data)
                    a.data[2] |= 0xE0            # ParamKind bits -> 7: decode fails
                    e2e_protect(a.data, 0x300, a.data[1] & 0x0F)
                out.append(a)
        i += 1
    # reordering: swap neighbours, move a frame a few places later
    for _ in range(int(rates["swap"] * len(out))):
        k = int(rng.integers(0, max(1, len(out) - 6)))
        j = k + int(rng.integers(1, 6))
        if j < len(out):
            out[k], out[j] = out[j], out[k]
    # the sample rate changes: from a frame on, times stretch (intervals of 1.3 - 2 periods
    # with counters advancing by one: the period rules, not the counter rules)
    if rng.random() < rates["stretch"] and len(out) > 20:
        k = int(rng.integers(5, len(out) - 5))
        f = float(rng.choice([0.5, 1.3, 1.52, 1.6, 2.0]))
        t_k = out[k].timestamp
        if math.isfinite(t_k):
            for m in out[k:]:
                m.timestamp = t_k + (m.timestamp - t_k) * f
    # a silence of exactly 15 or 30 samples (a bus-off): the counter shows advance 1
    if rng.random() < rates["silence"] and len(out) > 200:
        t_a = out[int(rng.integers(0, len(out) - 150))].timestamp
        span = int(rng.choice([15, 30])) / FS - 1e-6
        out = [m for m in out if not t_a <= m.timestamp < t_a + span]
    # a clock reset: a block of the stream stamped from an earlier origin
    if rng.random() < rates["reset"] and len(out) > 40:
        k = int(rng.integers(10, len(out) - 20))
        back = float(rng.uniform(0.1, 2.0))
        for m in out[k:]:
            m.timestamp -= back
    return out


def _stream(seed: int, n: int, rates: dict[str, float], tick_mode: bool,
            restart: bool) -> list[can.Message]:
    rng = np.random.default_rng(seed)
    channels = ["x1", "x2", "x1_ddot", "r"] if rng.random() < 0.7 else ["x1", "r", "r_dot"]
    frames = _node_stream(rng, n, channels)
    if restart:   # the node reboots: ticks and counters restart, time goes on
        t_last = frames[-1].timestamp
        frames += _node_stream(rng, n // 2, channels, tick0=0,
                               t0=t_last + float(rng.uniform(0.002, 0.3)))
    return _corrupt(rng, frames, rates, tick_mode)


RATES = st.fixed_dictionaries({
    "drop": st.sampled_from([0.0, 0.005, 0.03, 0.2]),
    "burst": st.sampled_from([0.0, 0.002, 0.01]),
    "flip": st.sampled_from([0.0, 0.005, 0.05]),
    "dlc": st.sampled_from([0.0, 0.003, 0.02]),
    "time": st.sampled_from([0.0, 0.002, 0.02]),
    "jitter": st.sampled_from([0.0, 0.1, 0.6]),
    "dup": st.sampled_from([0.0, 0.005, 0.05]),
    "foreign": st.sampled_from([0.0, 0.01, 0.05]),
    "swap": st.sampled_from([0.0, 0.002, 0.02]),
    "reset": st.sampled_from([0.0, 0.5]),
    "stretch": st.sampled_from([0.0, 0.5]),
    "silence": st.sampled_from([0.0, 0.7]),
})


def _listeners(time_source: str, capacity: int, growable: bool, max_delta: int,
               **kw: object) -> tuple[DecodeListener, DecodeListener]:
    ref = frame_by_frame(DecodeListener("quarter2", DB, capacity=capacity, growable=growable,
                                        time_source=time_source,  # type: ignore[arg-type]
                                        max_counter_delta=max_delta, batch_size=1))
    lst = DecodeListener("quarter2", DB, capacity=capacity, growable=growable,
                         time_source=time_source, max_counter_delta=max_delta,  # type: ignore[arg-type]
                         **kw)  # type: ignore[arg-type]
    return ref, lst


@_SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(20, 400), rates=RATES,
       time_source=st.sampled_from(["timestamp", "tick"]), restart=st.booleans(),
       capacity=st.sampled_from([16, 128, 4096]), growable=st.booleans(),
       max_delta=st.integers(1, 6), batch=st.sampled_from([1, 7, 64, 300, 2048]),
       reads=st.integers(0, 6))
def test_batches_equal_frame_by_frame(seed: int, n: int, rates: dict[str, float],
                                      time_source: str, restart: bool, capacity: int,
                                      growable: bool, max_delta: int, batch: int,
                                      reads: int) -> None:
    frames = _stream(seed, n, rates, time_source == "tick", restart)
    ref, lst = _listeners(time_source, capacity, growable, max_delta, batch_size=batch)
    for m in frames:
        ref.on_message_received(m)
    rng = np.random.default_rng(seed + 1)
    cuts = set(rng.integers(0, len(frames) + 1, reads).tolist())
    for i, m in enumerate(frames):
        if i in cuts:
            lst.counts   # a reader in the middle: processes the queue so far
        lst.on_message_received(m)
    assert snapshot(lst) == snapshot(ref)


@_SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(20, 400), rates=RATES,
       time_source=st.sampled_from(["timestamp", "tick"]), restart=st.booleans(),
       capacity=st.sampled_from([16, 4096]), growable=st.booleans(),
       chunks=st.lists(st.integers(1, 900), min_size=1, max_size=6))
def test_arrays_equal_frame_by_frame(seed: int, n: int, rates: dict[str, float],
                                     time_source: str, restart: bool, capacity: int,
                                     growable: bool, chunks: list[int]) -> None:
    """``feed_arrays`` on FrameArrays cut anywhere."""
    frames = _stream(seed, n, rates, time_source == "tick", restart)
    ref, lst = _listeners(time_source, capacity, growable, 4)
    for m in frames:
        ref.on_message_received(m)
    feed_in_chunks(lst, FrameArrays.from_messages(frames), chunks)
    assert snapshot(lst) == snapshot(ref)


@pytest.mark.parametrize("time_source", ["timestamp", "tick"])
@pytest.mark.parametrize("faults", [[], ["loss=0.02", "bitflip=0.01"],
                                    ["burst=2:0.05", "late=0.02:0.004", "busoff=1.0:0.3"]])
def test_node_with_faults_equal(time_source: str, faults: list[str]) -> None:
    """The simulated node's own fault injection (loss, bursts, bit flips, late frames)."""
    node = SensorNode(NodeConfig(scenario="random", duration=3.0, rate=500.0,
                                 faults=FaultConfig.parse(faults), seed=3))
    frames = list(node.frames())
    for batch in (256, 2048):
        ref, lst = _listeners(time_source, 512, False, 4, batch_size=batch)
        for m in frames:
            ref.on_message_received(m)
            lst.on_message_received(m)
        assert snapshot(lst) == snapshot(ref)


def _write_candump(path: Path, frames: list[can.Message]) -> None:
    """candump -L lines (µs timestamps) for the frames, the way the log writer spells them."""
    lines = []
    for m in frames:
        if m.is_error_frame:
            lines.append(f"({m.timestamp:.6f}) can0 20000080#0000000000000000")
        elif m.is_remote_frame:
            lines.append(f"({m.timestamp:.6f}) can0 {m.arbitration_id:03X}#R")
        elif m.is_fd:
            lines.append(f"({m.timestamp:.6f}) can0 {m.arbitration_id:03X}##0{m.data.hex()}")
        else:
            fid = f"{m.arbitration_id:08X}" if m.is_extended_id else f"{m.arbitration_id:03X}"
            lines.append(f"({m.timestamp:.6f}) can0 {fid}#{m.data.hex().upper()}")
    path.write_text("\n".join(lines) + "\n")


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), rates=RATES,
       time_source=st.sampled_from(["timestamp", "tick"]), garbage=st.integers(0, 5))
def test_log_arrays_equal_messages(tmp_path: Path, seed: int, rates: dict[str, float],
                                   time_source: str, garbage: int) -> None:
    """A candump log: feed_log (array reader + batches) = read_log messages one by one."""
    frames = [m for m in _stream(seed, 200, rates, time_source == "tick", False)
              if math.isfinite(m.timestamp) and m.timestamp >= 0]
    path = tmp_path / f"s{seed}.log"
    _write_candump(path, frames)
    truncate_lines(path, seed, garbage)
    assert_feed_log_equals_messages(path, time_source)


def truncate_lines(path: Path, seed: int, count: int) -> None:
    """Cut ``count`` random lines of a text log short (damaged records)."""
    if not count:
        return
    rng = np.random.default_rng(seed)
    lines = path.read_text().splitlines()
    for _ in range(count):
        k = int(rng.integers(0, len(lines)))
        lines[k] = lines[k][:int(rng.integers(0, len(lines[k]) + 1))]   # truncated line
    path.write_text("\n".join(lines) + "\n")


def assert_feed_log_equals_messages(path: Path, time_source: str) -> None:
    """``feed_log`` (array reader + batches) leaves a listener exactly as ``read_log``
    messages fed one by one do: read statistics and every observable state."""
    ref, lst = _listeners(time_source, 4096, False, 4)
    s_ref = ReadStats()
    for m in read_log(path, s_ref):
        ref.on_message_received(m)
    ref.count_malformed(s_ref.malformed)
    s_arr = ReadStats()
    feed_log(lst, path, s_arr)
    lst.count_malformed(s_arr.malformed)
    assert s_arr == s_ref
    assert snapshot(lst) == snapshot(ref)
