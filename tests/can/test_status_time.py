"""SN_Status on the sensor's clock: a host that delivers the node's frames late, in a bunch,
loses no status frame; status frames that really are missing are still counted lost.

The node sends SN_Status (its own alive counter, 10 Hz) in the sensor task's tick, right
after that tick's SN_Sync. In tick mode the decoder times it by the last SN_Sync's tick; by
its arrival time, a pause of 16 status periods in the delivery read as the 15 frames a 4-bit
counter cannot show (a silence whose length in periods is 1 mod 15).
"""
from __future__ import annotations

from pathlib import Path

import can
import numpy as np
import pytest

from estimator.decode import DecodeListener, feed_log
from firmware_sim.node import NodeConfig, SensorNode
from suspid.can.dbc import STATUS_MESSAGE, load_dbc
from suspid.can.logs import FrameArrays

from tests.can.frame_by_frame import frame_by_frame
from tests.can.test_batch_equivalence import _write_candump, snapshot

DB = load_dbc()
STATUS_ID = DB.get_message_by_name(STATUS_MESSAGE).frame_id
#: the host stalls from just after the status of t = 2.0 s for 16 status periods
STALL_FROM, STALL = 2.001, 1.6


@pytest.fixture(scope="module")
def node_frames() -> list[can.Message]:
    """6 s of a 500 Hz quarter-car node (status every 50 ticks), stamped with data time."""
    node = SensorNode(NodeConfig(scenario="random", duration=6.0, rate=500.0, seed=5))
    return list(node.frames())


def _copy(m: can.Message, t: float) -> can.Message:
    return can.Message(timestamp=t, arbitration_id=m.arbitration_id,
                       is_extended_id=m.is_extended_id, data=bytearray(m.data), check=False)


def _stalled(frames: list[can.Message]) -> list[can.Message]:
    """Every frame sent during the stall arrives at its end, all at once (order kept)."""
    end = STALL_FROM + STALL
    return [_copy(m, end if STALL_FROM <= m.timestamp < end else m.timestamp) for m in frames]


def _without_status(frames: list[can.Message], n: int) -> list[can.Message]:
    """The ``n`` status frames after the one at t = 2.0 s lost at the sender."""
    gone = {round(2.0 + 0.1 * k, 6) for k in range(1, n + 1)}
    return [m for m in frames
            if not (m.arbitration_id == STATUS_ID and round(m.timestamp, 6) in gone)]


def _decode(frames: list[can.Message], time_source: str) -> tuple[DecodeListener, DecodeListener]:
    """Frame by frame (the oracle) and in batches through the engine."""
    ref = frame_by_frame(DecodeListener("quarter2", DB, time_source=time_source,  # type: ignore[arg-type]
                                        batch_size=1))
    for m in frames:
        ref.on_message_received(m)
    lst = DecodeListener("quarter2", DB, time_source=time_source)  # type: ignore[arg-type]
    lst.feed_arrays(FrameArrays.from_messages(frames))
    lst.counts   # processes what is queued
    return ref, lst


def test_the_stall_delays_sixteen_status_periods(node_frames: list[can.Message]) -> None:
    """The test's premise: by arrival, a status follows the one before 16 periods later."""
    st = [m.timestamp for m in _stalled(node_frames) if m.arbitration_id == STATUS_ID]
    assert max(np.diff(st)) == pytest.approx(16 * 0.1, abs=2e-3)
    assert round(max(np.diff(st)) / 0.1) % 15 == 1


@pytest.mark.parametrize("time_source", ["tick", "auto"])
def test_late_delivery_loses_no_status_frame(node_frames: list[can.Message],
                                             time_source: str) -> None:
    clean_ref, _ = _decode(node_frames, time_source)
    for lst in _decode(_stalled(node_frames), time_source):
        st = lst.frame_stats()
        assert st["time_base"] == "tick"
        assert st["lost"] == 0
        assert sum(st["rejected"].values()) == 0   # type: ignore[attr-defined]
        assert st["accepted"] == len(node_frames)
        assert lst.per_message() == clean_ref.per_message()
        # the data and the status state are the clean stream's
        for name, src in clean_ref.buffer.sources.items():
            t0, v0 = src.snapshot()
            t1, v1 = lst.buffer.sources[name].snapshot()
            np.testing.assert_array_equal(t1, t0)
            np.testing.assert_array_equal(v1, v0)
        assert lst.node_status == clean_ref.node_status
    ref, lst = _decode(_stalled(node_frames), time_source)
    assert snapshot(lst) == snapshot(ref)


@pytest.mark.parametrize("n_lost", [15, 16, 3])
@pytest.mark.parametrize("stalled", [False, True])
def test_missing_status_frames_are_still_lost(node_frames: list[can.Message], n_lost: int,
                                              stalled: bool) -> None:
    """15 missing frames (the counter shows an advance of 1), 16 and 3: counted from the
    sensor's clock, with or without the late delivery on top."""
    frames = _without_status(node_frames, n_lost)
    assert len(frames) == len(node_frames) - n_lost
    if stalled:
        frames = _stalled(frames)
    ref, lst = _decode(frames, "tick")
    for d in (ref, lst):
        st = d.frame_stats()
        assert st["lost"] == n_lost
        assert sum(st["rejected"].values()) == 0   # type: ignore[attr-defined]
        assert st["accepted"] == len(frames)
    assert snapshot(lst) == snapshot(ref)


def test_stalled_log_file(node_frames: list[can.Message], tmp_path: Path) -> None:
    """The same through a candump log (the array reader and its batches)."""
    path = tmp_path / "stalled.log"
    _write_candump(path, _stalled(node_frames))
    lst = DecodeListener("quarter2", DB, time_source="auto")
    feed_log(lst, path)
    st = lst.frame_stats()
    assert st["time_base"] == "tick"
    assert st["lost"] == 0 and st["accepted"] == len(node_frames)


def test_status_time_is_the_sync_tick(node_frames: list[can.Message]) -> None:
    """The last status (the stopping one, sent in the last tick) carries that tick's time,
    whatever its arrival."""
    late = [_copy(m, m.timestamp + 3.0) for m in node_frames]
    for lst in _decode(late, "tick"):
        assert lst.node_status["state"] == 4
        assert lst.node_status["t"] == pytest.approx(node_frames[-1].timestamp, abs=1e-9)
    for lst in _decode(late, "timestamp"):
        assert lst.node_status["t"] == pytest.approx(node_frames[-1].timestamp + 3.0, abs=1e-9)
