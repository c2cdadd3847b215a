"""Sample slots from arrival times on a live bus (:mod:`estimator.decode.rules.arrival_live`):
frames handed over one by one (``DecodeListener.on_message_received``, the path after the
bus) are placed as a whole log is, so arrival jitter, bursts and delivery delay lose no
sample and change no estimate in the live monitor."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import can
import numpy as np
import pytest

import estimator.stream.pipeline as pipeline
from estimator.decode import DecodeListener, ReplayBus, feed_log
from estimator.decode.rules.arrival import MIN_FRAMES
from estimator.decode.rules.arrival_live import HOLD, LiveSlots
from tests.can.test_arrival_time import KINDS, P, _arrivals, _rel, logs  # noqa: F401
from tests.can.test_time_base import FIX, _estimates
from tests.conftest import write_config

ALL = ["clean", *KINDS]


def _messages(path: Path) -> list[can.Message]:
    return list(can.LogReader(str(path)))


#: channels the DBC maps for quarter2 that the node does not send by default (ride heights)
NOT_SENT = ("d", "d_dot")


def _listener() -> DecodeListener:
    return DecodeListener("quarter2", capacity=1 << 14, growable=True,
                          time_source="timestamp", arrival_slots=True)


def _samples(listener: DecodeListener) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The samples of every ring that received frames (a DBC message the log lacks, e.g. a
    ride height the node did not send, has none)."""
    return {name: src.snapshot() for name, src in listener.buffer.sources.items() if src.n}


# ---- the rule on synthetic arrival times ---------------------------------------------------
@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize("kind", ["clean", *KINDS])
def test_online_slots_equal_the_true_ones(kind: str, seed: int) -> None:
    t, k = _arrivals(kind, 4000, P, (2500, 50), seed)
    ls = LiveSlots("m")
    out: list[tuple[float, int, Any]] = []
    for i, x in enumerate(t):
        ls.push(float(x), i, out)
    ls.flush(out)
    assert len(out) == t.size and [o[2] for o in out] == list(range(t.size))
    if kind == "clean":
        assert ls.state == "kept"          # on their grid: the timestamps are kept
        return
    got = np.array([o[1] for o in out])
    wrong = np.flatnonzero(got != k)
    # as offline: frames delayed next to the gap may be read on either side of it
    assert wrong.size <= 5 and (wrong.size == 0 or abs(int(wrong.mean()) - 2500) < 40)
    assert ls.missing == 50 and ls.period == pytest.approx(P, rel=1e-9)


# ---- frame by frame equals the whole log ---------------------------------------------------
@pytest.mark.parametrize("kind", ALL)
def test_frame_by_frame_equals_the_log_path(logs: dict[str, Path], kind: str) -> None:  # noqa: F811
    off = _listener()
    feed_log(off, logs[kind])
    live = _listener()
    msgs = _messages(logs[kind])
    for m in msgs:
        live.on_message_received(m)
    # before the end: what was passed on is final (a prefix of every message's samples),
    # held back are at most the look-ahead of each message plus the merge's wait
    before = _samples(live)
    live.finish()
    after, ref = _samples(live), _samples(off)
    for name, (t, v) in ref.items():
        tb, vb = before[name]
        assert t.size - tb.size <= 2 * HOLD, name
        np.testing.assert_array_equal(after[name][0][:tb.size], tb)
        ta, va = after[name]
        assert ta.size == t.size, name                       # no frame lost
        np.testing.assert_array_equal(va, v)                  # the same samples, in order
        # the same slots: the data times differ by the envelope's estimate only
        assert np.abs(ta - t).max() < 0.5 * P, name
    fs, fo = live.frame_stats(), off.frame_stats()
    assert fs["time_base"] == fo["time_base"] == "timestamp"
    assert fs["accepted"] == fo["accepted"] and sum(fs["rejected"].values()) == 0  # type: ignore[attr-defined]
    slots = fs["arrival_slots"]
    assert set(slots) == set(fo["arrival_slots"])            # type: ignore[arg-type]
    for v in slots.values():                                 # type: ignore[attr-defined]
        assert v["missing"] == 0 and v["retimed"] == (kind != "clean")
        assert v["period"] == pytest.approx(P, rel=1e-9)
    # on the grid: every sample in its own cell, the values the log path gives
    a, b = off.aligned(), live.aligned()
    assert a.t.size == b.t.size
    for ch, v in a.values.items():
        np.testing.assert_array_equal(b.values[ch], v)
        if ch not in NOT_SENT:
            assert not np.isnan(b.values[ch]).any()


def test_a_real_gap_live(logs: dict[str, Path]) -> None:  # noqa: F811
    off = _listener()
    feed_log(off, logs["gap"])
    live = _listener()
    for m in _messages(logs["gap"]):
        live.on_message_received(m)
    live.finish()
    fs = live.frame_stats()
    slots = fs["arrival_slots"]
    assert all(v["missing"] == 50 for v in slots.values())   # type: ignore[attr-defined]
    # a jittered frame next to the gap may be read on either side of it (arrival times
    # cannot tell); read on the other side than offline, the node's alive counter then
    # rejects it (counter_jump): at most one frame per message
    assert off.frame_stats()["accepted"] - fs["accepted"] <= 3   # type: ignore[operator]
    al = live.aligned()
    for ch, v in al.values.items():
        if ch in NOT_SENT:
            continue
        miss = np.flatnonzero(np.isnan(v))
        assert 50 <= miss.size <= 51 and miss[-1] - miss[0] == miss.size - 1, ch


# ---- the live monitor: receiver thread, frame by frame, windows ----------------------------
@pytest.mark.parametrize("kind", ALL)
def test_live_monitor_gives_the_clean_estimates(logs: dict[str, Path], kind: str,  # noqa: F811
                                                monkeypatch: pytest.MonkeyPatch,
                                                capsys: pytest.CaptureFixture[str],
                                                tmp_path: Path) -> None:
    """``suspid monitor --interface ...`` with ``[live] time_source = "timestamp"`` on a bus
    that delivers the
    stream with its transport's timestamps (python-can's virtual bus stamps frames with the
    host clock when sent, so the frames come from a read-only bus that keeps them)."""
    msgs = _messages(logs[kind])
    monkeypatch.setattr(pipeline, "open_checked_bus",
                        lambda *a, **k: ReplayBus(msgs, channel="live"))
    mon = ["monitor", "--model", "quarter2", *FIX, "--fix", "c2=300", "--fix", "k2=200000",
           "--window", "2", "--step", "1", "--jsonl", "--no-inspection"]
    ref = _estimates([*mon, "--input", str(logs["clean"])], capsys)
    got = _estimates([*mon, "--interface", "virtual", "--channel", "live",
                      "--config", write_config(tmp_path, '[live]\ntime_source = "timestamp"\n'
                                                         "idle_timeout_s = 1\n")], capsys)
    frames = got[-1]["frames"]
    assert frames["time_base"] == "timestamp"                # type: ignore[index]
    assert sum(frames["rejected"].values()) == 0             # type: ignore[index]
    assert frames["accepted"] == ref[-1]["frames"]["accepted"]   # type: ignore[index]
    assert len(got) == len(ref) >= 6
    for x, y in zip(ref[:-1], got[:-1]):
        if kind == "clean":      # a clean stream: the very same windows
            assert y["t"] == x["t"] and y["params"] == x["params"]
        else:
            assert abs(y["t"] - 100.0 - x["t"]) < 5 * P       # type: ignore[operator]
            assert _rel(x["params"], y["params"]) <= 1e-6     # type: ignore[arg-type]


def test_a_clock_reset_starts_the_rule_over(logs: dict[str, Path]) -> None:  # noqa: F811
    """A logger clock that jumps back: the held frames are passed on, the rule starts over
    on the new clock, and the decoder's time check re-anchors as without the slots."""
    msgs = _messages(logs["jitter"])
    half = len(msgs) // 2
    for m in msgs[half:]:
        m.timestamp -= 1000.0
    got = {}
    for slots in (False, True):
        lis = DecodeListener("quarter2", capacity=1 << 14, growable=True,
                             time_source="timestamp", arrival_slots=slots)
        for m in msgs:
            lis.on_message_received(m)
        lis.finish()
        got[slots] = lis.frame_stats()
    assert got[True]["accepted"] >= got[False]["accepted"]            # type: ignore[operator]
    assert got[True]["accepted"] >= len(msgs) - 32                    # type: ignore[operator]
    assert all(v["retimed"] for v in got[True]["arrival_slots"].values())  # type: ignore[attr-defined]


def test_a_slow_message_ends_its_warm_up_in_time() -> None:
    """A message at 2 Hz is placed after WARMUP_S of arrival time (and 2 x MIN_FRAMES
    frames), not after WARMUP frames."""
    t, k = _arrivals("jitter", 40, 0.5, None, 3)
    ls = LiveSlots("slow")
    out: list[tuple[float, int, Any]] = []
    for i, x in enumerate(t):
        ls.push(float(x), i, out)
        if i == 2 * MIN_FRAMES - 1:
            assert ls.state == "placing" and out
    ls.flush(out)
    np.testing.assert_array_equal([o[1] for o in out], k)
