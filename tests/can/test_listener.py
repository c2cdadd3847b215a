"""Frame validation (every rejection class), decoding, rolling buffer, alignment, gaps."""
from __future__ import annotations

import math
import time

import can
import numpy as np
import pytest

from estimator.decode import DecodeListener, RollingBuffer, feed, feed_with_notifier
from suspid.can.codec import SensorEncoder, make_message
from suspid.can.crc import e2e_crc, e2e_protect
from suspid.errors import InputError, UsageError
from tests.can.frame_by_frame import push_one

FS = 500.0


def _frames(db, n=40, t0=0.0, channels=("x1", "x2", "r")):
    """Sync + QC frames of n samples, values = sample index in mm (mod 300, inside the range)."""
    enc = SensorEncoder(db, "quarter2", list(channels))
    out = []
    for k in range(n):
        t = t0 + k / FS
        fid, data = enc.sync_frame(k, 1 / FS)
        out.append(make_message(fid, data, t))
        for fid, data in enc.sample_frames(k, {c: (k % 300) * 1e-3 for c in channels}):
            out.append(make_message(fid, data, t))
    return out


def _listener(db, **kw):
    return DecodeListener("quarter2", db, **kw)


def test_clean_stream_all_accepted(db):
    frames = _frames(db)
    lst = _listener(db)
    feed(lst, frames)
    st = lst.frame_stats()
    assert st["accepted"] == len(frames) and sum(st["rejected"].values()) == 0
    al = lst.aligned()
    assert al.dt == pytest.approx(1 / FS)
    np.testing.assert_allclose(al.values["x1"], np.arange(40) * 1e-3, atol=5e-6)
    # channels that were not sent (Valid = 0, or no frame of their message: the ride
    # height) are one gap over the whole record
    assert {g.channel for g in al.gaps} == {"x1_dot", "x1_ddot", "x2_dot", "x2_ddot", "r_dot",
                                            "d", "d_dot"}
    assert all(g.samples == 40 for g in al.gaps)


def _reasons(lst):
    return {k: v for k, v in lst.frame_stats()["rejected"].items() if v}


def test_crc_corruption_rejected_and_next_frame_accepted(db):
    frames = _frames(db)
    bad = frames[21]                      # a QC_Body frame (sample 5)
    assert bad.arbitration_id == 0x110
    bad.data[3] ^= 0x04
    lst = _listener(db)
    feed(lst, frames)
    assert _reasons(lst) == {"crc": 1}
    assert lst.frame_stats()["lost"] == 1  # the next QC_Body has counter + 2
    al = lst.aligned()
    assert np.isnan(al.values["x1"][5]) and not np.isnan(al.values["x1"][6])
    assert [(g.channel, g.samples) for g in al.gaps if g.channel == "x1"] == [("x1", 1)]


def test_wrong_dlc_foreign_id_error_and_remote_frames(db):
    frames = _frames(db, 10)
    short = frames[5]
    short.data = short.data[:6]
    short.dlc = 6
    extra = [can.Message(timestamp=frames[-1].timestamp, arbitration_id=0x7DF, data=bytes(8)),
             can.Message(timestamp=frames[-1].timestamp, arbitration_id=0x110,
                         is_extended_id=True, data=bytes(8)),  # same number, extended: foreign
             can.Message(timestamp=frames[-1].timestamp, is_error_frame=True),
             can.Message(timestamp=frames[-1].timestamp, arbitration_id=0x110,
                         is_remote_frame=True, dlc=8)]
    lst = _listener(db)
    feed(lst, frames + extra)
    assert _reasons(lst) == {"dlc": 1, "unknown_id": 2, "frame_type": 2}


def test_counter_jump_stale_and_invalid(db):
    frames = _frames(db, 12)
    body = [m for m in frames if m.arbitration_id == 0x110]

    def set_counter(msg, c):
        e2e_protect(msg.data, 0x110, c)

    set_counter(body[4], (4 + 7) % 15)     # jumps by 7, one period later: rejected, resync
    set_counter(body[8], 7)                # repeats the counter of body[7]: stale
    body[10].data[1] |= 0x0F               # counter 15 is invalid (CRC recomputed)
    body[10].data[0] = e2e_crc(0x110, body[10].data)
    lst = _listener(db)
    feed(lst, frames)
    r = _reasons(lst)
    assert lst.per_message()["QC_Body"] == 12 - 4
    # body[4] jumps (rejected, re-synchronises on 11), body[5] (counter 5) then jumps too
    # (rejected, re-synchronises on 5); body[8] repeats 7; body[10] has the invalid 15
    assert r == {"counter_jump": 3, "counter_stale": 1}


def test_time_going_backwards_rejected(db):
    frames = _frames(db, 10)
    frames[13].timestamp -= 0.5
    lst = _listener(db)
    feed(lst, frames)
    assert _reasons(lst) == {"time": 1}


def test_gap_in_time_is_accepted_when_counter_matches(db):
    # samples 5..15 lost (11 frames per ID): a 4-bit counter alone would read the advance
    # of 12 as "3 steps back"; the time since the last frame says 12 periods
    frames = [m for m in _frames(db, 30) if not 5 <= round(m.timestamp * FS) <= 15]
    lst = _listener(db)
    feed(lst, frames)
    assert _reasons(lst) == {}
    assert lst.frame_stats()["lost"] == 4 * 11
    al = lst.aligned()
    assert np.isnan(al.values["x1"][5:16]).all() and not np.isnan(al.values["x1"][16:]).any()


def test_tick_time_source_ignores_arrival_times(db):
    frames = _frames(db, 40)
    for m in frames:  # e.g. --speed max: every frame arrives at the same wall time
        m.timestamp = 100.0
    lst = _listener(db, time_source="tick")
    feed(lst, frames)
    al = lst.aligned()
    np.testing.assert_allclose(al.t, np.arange(40) / FS, atol=1e-12)
    np.testing.assert_allclose(al.values["x1"], np.arange(40) * 1e-3, atol=5e-6)


def test_tick_mode_needs_sync_first(db):
    frames = [m for m in _frames(db, 5) if m.arbitration_id != 0x100][:3]
    lst = _listener(db, time_source="tick")
    feed(lst, frames)
    assert _reasons(lst) == {"no_sync": 3}


def test_notifier_path_equals_direct_feed(db):
    frames = _frames(db, 200)
    a, b = _listener(db), _listener(db)
    feed(a, frames)
    feed_with_notifier(b, frames)
    assert a.frame_stats() == b.frame_stats()
    for ch in ("x1", "x2", "r"):
        np.testing.assert_array_equal(a.aligned().values[ch], b.aligned().values[ch])


def test_live_virtual_bus_with_notifier(db):
    frames = _frames(db, 100)
    lst = _listener(db, time_source="tick")
    with can.Bus(interface="virtual", channel="t-live") as rx, \
            can.Bus(interface="virtual", channel="t-live") as tx:
        notifier = can.Notifier(rx, [lst])
        for m in frames:
            tx.send(m)
        deadline = time.monotonic() + 5
        while lst.counts.accepted < len(frames) and time.monotonic() < deadline:
            time.sleep(0.01)
        notifier.stop()
    assert lst.counts.accepted == len(frames)
    np.testing.assert_allclose(lst.aligned().t, np.arange(100) / FS, atol=1e-12)


def test_rolling_buffer_is_bounded():
    buf = RollingBuffer(capacity=64)
    src = buf.source("m", ["a", "b"])
    for k in range(1000):
        push_one(src, k * 0.01, (float(k), -float(k)))
    assert buf.overwritten == 1000 - 64
    t, v = buf.series("a")
    np.testing.assert_array_equal(v, np.arange(936, 1000))
    al = buf.align(["a", "b"])
    assert al.t.size == 64 and al.values["b"][-1] == -999.0
    win = buf.align(["a"], t_start=9.895, t_end=9.955)
    np.testing.assert_array_equal(win.values["a"], [990, 991, 992, 993, 994, 995])


def test_window_alignment_marks_gaps_not_interpolates(db):
    frames = [m for m in _frames(db, 50) if not (m.arbitration_id == 0x111
                                                 and 20 / FS <= m.timestamp < 23 / FS)]
    lst = _listener(db, max_counter_delta=4)
    feed(lst, frames)
    al = lst.aligned(window=40 / FS)
    x2 = al.values["x2"]
    assert np.isnan(x2).sum() == 3
    gaps = [g for g in al.gaps if g.channel == "x2"]
    assert len(gaps) == 1 and gaps[0].samples == 3 and gaps[0].t_start == pytest.approx(20 / FS)


def test_foreign_dbc_requires_a_map_and_mean_offset(realdata):
    with pytest.raises(UsageError, match="signal map"):
        DecodeListener("quarter2", realdata / "canedge-imu" / "canmod-gps.dbc")
    lst = DecodeListener("quarter2", realdata / "canedge-imu" / "canmod-gps.dbc",
                         ["x1_ddot=gnss_imu.AccelerationX-mean"])
    assert lst.mean_channels == ["x1_ddot"]


def test_empty_buffer_alignment_is_input_error(db):
    with pytest.raises(InputError, match="no decoded samples"):
        _listener(db).aligned()
    assert math.isnan(RollingBuffer(4).latest_time())


def test_align_while_frames_arrive_from_another_thread(db):
    import threading

    frames = _frames(db, 2000)
    lst = _listener(db, capacity=16, growable=True)  # grows ~7 times meanwhile
    errors: list[BaseException] = []
    done = threading.Event()

    def consumer():
        while not done.is_set():
            try:
                if lst.counts.accepted > 8:
                    al = lst.aligned(window=0.1)
                    assert not np.isnan(al.values["x1"]).all()
            except BaseException as exc:  # noqa: BLE001 - reported below
                errors.append(exc)
                return

    th = threading.Thread(target=consumer)
    th.start()
    feed(lst, frames)
    done.set()
    th.join()
    assert errors == []
    assert lst.counts.accepted == len(frames) and lst.buffer.overwritten == 0
