"""Fuzzing the frame validator/decoder and the tolerant log readers.

Invariant of :class:`estimator.decode.DecodeListener`: every frame it is given is either
accepted, ignored (a DBC message without mapped channels) or counted under exactly one
rejection reason -- nothing raises, and the counts add up.
"""
from __future__ import annotations

import math
from pathlib import Path

import can
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from estimator.decode import DecodeListener, feed
from estimator.decode.buffer import Aligned
from suspid.can.codec import SensorEncoder, make_message
from suspid.can.crc import e2e_protect
from suspid.can.dbc import load_dbc
from suspid.can.logs import ReadStats, open_log_writer, read_log
from suspid.errors import InputError

DB = load_dbc()
KNOWN_IDS = sorted({m.frame_id for m in DB.messages})
FS = 500.0
_SETTINGS = settings(max_examples=60, deadline=None,
                     suppress_health_check=[HealthCheck.function_scoped_fixture])

TIMES = st.one_of(st.floats(-5.0, 5.0), st.sampled_from([math.nan, math.inf, -math.inf, 0.0,
                                                          1e6, -1e6, 1e300]))


def _align_or_outlier(lst: DecodeListener) -> Aligned | None:
    """``lst.aligned()``, or ``None`` if it refused a timestamp outlier (one InputError line)."""
    try:
        return lst.aligned()
    except InputError as exc:
        assert "timestamp outlier" in str(exc) and "\n" not in str(exc)
        return None


def _accounted(lst: DecodeListener) -> int:
    st_ = lst.frame_stats()
    return st_["accepted"] + st_["ignored"] + sum(st_["rejected"].values())  # type: ignore[operator]


def _clean(n: int, channels: tuple[str, ...] = ("x1", "x2", "r"), t0: float = 0.0,
           tick0: int = 0) -> list[can.Message]:
    """Sync + QC frames of ``n`` samples of a valid stream."""
    enc = SensorEncoder(DB, "quarter2", list(channels))
    out = []
    for k in range(n):
        t = t0 + k / FS
        fid, data = enc.sync_frame(tick0 + k, 1 / FS)
        out.append(make_message(fid, data, t))
        for fid, data in enc.sample_frames(tick0 + k, {c: 1e-3 * (k % 100) for c in channels}):
            out.append(make_message(fid, data, t))
    return out


@st.composite
def random_frame(draw: st.DrawFn) -> can.Message:
    """Any frame: known or random ID, any DLC, random payload (sometimes E2E-valid), any time."""
    fid = draw(st.one_of(st.sampled_from(KNOWN_IDS), st.integers(0, 0x7FF),
                         st.integers(0, 0x1FFFFFFF)))
    ext = fid > 0x7FF or draw(st.booleans())
    data = bytearray(draw(st.binary(min_size=0, max_size=8)))
    if len(data) >= 2 and draw(st.booleans()):
        e2e_protect(data, fid & 0x7FF, draw(st.integers(0, 15)) % 15)  # passes the CRC check
    kind = draw(st.sampled_from(["data"] * 8 + ["error", "remote"]))
    return can.Message(timestamp=draw(TIMES), arbitration_id=fid, is_extended_id=ext,
                       data=data, is_error_frame=kind == "error",
                       is_remote_frame=kind == "remote", check=False)


@_SETTINGS
@given(frames=st.lists(random_frame(), max_size=60),
       time_source=st.sampled_from(["timestamp", "tick"]))
def test_random_frames_are_counted_never_raise(frames: list[can.Message], time_source: str) -> None:
    lst = DecodeListener("quarter2", DB, capacity=64, time_source=time_source)  # type: ignore[arg-type]
    feed(lst, frames)
    assert _accounted(lst) == len(frames) == lst.frames
    # the buffer never holds a non-finite time
    for src in lst.buffer.sources.values():
        t, _ = src.snapshot()
        assert np.isfinite(t).all()
    if any(s.n for s in lst.buffer.sources.values()):
        al = _align_or_outlier(lst)
        if al is not None:
            assert np.isfinite(al.t).all() and al.t.size <= 2_000_001


@_SETTINGS
@given(data=st.data())
def test_perturbed_valid_stream_counts_add_up(data: st.DataObject) -> None:
    """Drop, duplicate, swap, retime and corrupt frames of a valid stream."""
    frames = _clean(60)
    ops = data.draw(st.lists(st.tuples(st.sampled_from(["drop", "dup", "swap", "time", "flip",
                                                        "dlc"]),
                                       st.integers(0, len(frames) - 2)), max_size=12))
    for op, k in ops:
        k = min(k, len(frames) - 2)
        m = frames[k]
        if op == "drop":
            del frames[k]
        elif op == "dup":
            frames.insert(k, can.Message(timestamp=m.timestamp, arbitration_id=m.arbitration_id, is_extended_id=False,
                                         data=bytes(m.data), check=False))
        elif op == "swap":
            frames[k], frames[k + 1] = frames[k + 1], frames[k]
        elif op == "time":
            m.timestamp = data.draw(TIMES)
        elif op == "flip":
            m.data = bytearray(m.data)
            bit = data.draw(st.integers(0, 8 * len(m.data) - 1))
            m.data[bit // 8] ^= 1 << (bit % 8)
        else:
            m.data = bytearray(m.data) + b"\x00" if len(m.data) < 8 else bytearray(m.data[:-1])
            m.dlc = len(m.data)
    lst = DecodeListener("quarter2", DB)
    feed(lst, frames)
    assert _accounted(lst) == len(frames)
    st_ = lst.frame_stats()
    n_ops = len(ops)
    # each perturbation costs at most a few frames: the stream re-synchronises
    assert st_["accepted"] >= len(frames) - 4 * n_ops - 16 * sum(op == "time" for op, _ in ops)
    al = _align_or_outlier(lst)
    if al is None:  # only a far-off timestamp can make the grid refuse
        assert any(op == "time" for op, _ in ops)
    else:
        assert np.isfinite(al.t).all() and al.t.size >= 1


def test_non_finite_timestamps_are_rejected_as_time() -> None:
    """Regression: a NaN timestamp used to be accepted and crash the alignment."""
    for bad in (math.nan, math.inf, -math.inf):
        frames = _clean(50)
        frames[41].timestamp = bad   # a data frame of sample 10
        lst = DecodeListener("quarter2", DB)
        feed(lst, frames)
        assert lst.frame_stats()["rejected"]["time"] == 1, bad
        assert lst.frame_stats()["accepted"] == len(frames) - 1
        al = lst.aligned()
        assert al.t.size == 50 and np.isfinite(al.t).all()
        assert int(np.isnan(al.values["x1"]).sum()) + int(np.isnan(al.values["x2"]).sum()) \
            + int(np.isnan(al.values["r"]).sum()) == 1  # the one dropped sample is a gap


def test_duplicate_timestamps_same_id_are_stale() -> None:
    frames = _clean(30)
    dup = [can.Message(timestamp=m.timestamp, arbitration_id=m.arbitration_id, is_extended_id=False, data=bytes(m.data),
                       check=False) for m in frames]
    lst = DecodeListener("quarter2", DB)
    feed(lst, [x for pair in zip(frames, dup) for x in pair])
    st_ = lst.frame_stats()
    assert st_["accepted"] == len(frames) and st_["rejected"]["counter_stale"] == len(frames)


# ---- log readers ---------------------------------------------------------------------
LINE = st.one_of(
    st.text(max_size=40),
    st.builds(lambda ts, i, d: f"({ts}) can0 {i}#{d}",
              st.one_of(st.floats(allow_nan=True).map(repr), st.text("0123456789.-e", max_size=8)),
              st.text("0123456789ABCDEFxR#", max_size=9),
              st.text("0123456789abcdefR#", max_size=20)),
)


@_SETTINGS
@given(garbage=st.lists(LINE, max_size=20), where=st.lists(st.integers(0, 200), max_size=20))
def test_candump_garbage_lines_are_counted(tmp_path: Path, garbage: list[str],
                                           where: list[int]) -> None:
    good = [f"({k / FS:.6f}) can0 110#{'00' * 8}" for k in range(100)]
    lines = list(good)
    for g, w in zip(garbage, where + [0] * len(garbage)):
        lines.insert(min(w, len(lines)), g.replace("\n", " ").replace("\r", " "))
    p = tmp_path / "g.log"
    p.write_text("\n".join(lines) + "\n")
    stats = ReadStats()
    msgs = list(read_log(p, stats))
    nonblank = sum(1 for line in lines if line.split())
    assert stats.frames == len(msgs) and stats.frames + stats.malformed == nonblank
    assert len(msgs) >= len(good)   # a garbage line never costs a good one
    lst = DecodeListener("quarter2", DB)
    feed(lst, msgs)
    lst.count_malformed(stats.malformed)
    assert _accounted(lst) == len(msgs) + stats.malformed


@pytest.fixture(scope="module")
def asc_lines(tmp_path_factory: pytest.TempPathFactory) -> list[str]:
    p = tmp_path_factory.mktemp("asc") / "clean.asc"
    with open_log_writer(p) as w:
        for m in _clean(40):
            w.on_message_received(m)
    return p.read_text().splitlines()


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(garbage=st.lists(st.text(max_size=50).map(lambda s: " ".join(s.split())), min_size=1,
                        max_size=6),
       where=st.lists(st.integers(0, 160), min_size=6, max_size=6))
def test_asc_garbage_lines_skip_only_themselves(tmp_path: Path, asc_lines: list[str],
                                                garbage: list[str], where: list[int]) -> None:
    head = next(i for i, line in enumerate(asc_lines) if "Start of measurement" in line) + 1
    body = asc_lines[head:]
    n_good = sum(1 for line in body if " Rx " in line or " Tx " in line)
    for g, w in zip(garbage, where):
        body.insert(min(w, len(body)), g)
    p = tmp_path / "g.asc"
    p.write_text("\n".join(asc_lines[:head] + body) + "\n")
    stats = ReadStats()
    msgs = list(read_log(p, stats))
    assert len(msgs) == stats.frames
    assert len([m for m in msgs if not m.is_error_frame]) >= n_good
    assert stats.malformed <= len(garbage)


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf", ".trc", ".mf4"])
def test_empty_log_of_every_format(tmp_path: Path, suffix: str) -> None:
    """An empty log reads as no frames, or fails with one InputError line, never a traceback."""
    from estimator.decode.log_input import load_log_as_measurement

    p = tmp_path / f"empty{suffix}"
    p.write_bytes(b"")
    with pytest.raises(InputError) as ei:
        load_log_as_measurement(p, "quarter2")
    assert "\n" not in str(ei.value) and str(p) in str(ei.value)


@pytest.mark.parametrize("content,got", [
    (b"", "got an empty file"),
    (b"LOGG", "got 4 bytes beginning b'LOGG'"),
    (b"PK\x03\x04" + bytes(200), "got a file beginning b'PK\\x03\\x04'"),
])
def test_a_file_that_is_no_blf_says_what_it_got(tmp_path: Path, content: bytes, got: str) -> None:
    """A ``.blf`` without the BLF signature and header: expected vs got, not the struct
    module's 'unpack requires a buffer of 72 bytes'."""
    p = tmp_path / "drive.blf"
    p.write_bytes(content)
    with pytest.raises(InputError) as ei:
        list(read_log(p))
    msg = str(ei.value)
    assert msg.startswith(f"{p}: not a Vector BLF file: expected the signature b'LOGG' and a "
                          "144-byte header, ") and msg.endswith(got), msg
