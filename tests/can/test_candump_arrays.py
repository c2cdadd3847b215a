"""The candump -L array reader is a line-by-line reader, bit for bit, and fast on real logs.

The array reader (:func:`suspid.can.candump.read_candump_arrays`, behind ``feed_log``,
``identify``/``diagnose``/``monitor --input LOG``) must give the frames of a reader that
takes the log line by line through python-can's ``CanutilsLogReader``
(:func:`_line_reader`, the oracle) bit for bit, and that reader's timestamp is
``float(text)``. Real logs carry epoch times
(``(1631416514.717133)``: 16 digits), so these must not leave the column parser: that was
the case up to 15 digits only, which read such a log ~40x slower than one starting at 0.
Lines the column parser does not take (FD, remote, odd spacing, CR line breaks, garbage)
go through python-can's reader and are merged back in file order.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import suspid.can.candump as candump
from suspid.can.frames import select_messages
from suspid.can.logs import FrameArrays, ReadStats, read_candump_arrays
from tests.can.test_batch_equivalence import (RATES, _stream, _write_candump,
                                              assert_feed_log_equals_messages, truncate_lines)

EPOCH = 1631416514.717133

_FIELDS = ("timestamp", "arbitration_id", "is_extended", "frame_type", "length", "data")


def _arrays(path: Path, stats: ReadStats, chunk_bytes: int = 1 << 19) -> FrameArrays:
    parts = list(read_candump_arrays(path, stats, chunk_bytes=chunk_bytes))
    if not parts:
        return FrameArrays.empty()
    out = FrameArrays(*(np.concatenate([getattr(p, f) for p in parts]) for f in _FIELDS))
    o = 0
    for part in parts:
        out.long_data.update({o + j: v for j, v in part.long_data.items()})
        o += len(part)
    return out


def _assert_same_frames(a: FrameArrays, b: FrameArrays) -> None:
    assert len(a) == len(b)
    # timestamps bit for bit (NaN payloads and -0.0 included)
    np.testing.assert_array_equal(a.timestamp.view(np.int64), b.timestamp.view(np.int64))
    for f in _FIELDS[1:]:
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    assert a.long_data == b.long_data


def _line_reader(path: Path, stats: ReadStats) -> list:  # type: ignore[type-arg]
    """The oracle: every line of ``path`` through python-can's reader one by one
    (:func:`suspid.can.candump._candump_odd`), universal newlines as a text file reads them,
    frames counted per channel."""
    with path.open("r", encoding="ascii", errors="replace") as fh:
        odd = candump._candump_odd(path, ((n, n, line) for n, line in enumerate(fh, 1)), stats)
        return list(select_messages(path, ".log", (m for _, m in odd), stats, None))


def _check_log(path: Path, chunk_bytes: int = 1 << 19, slow: "_CountSlowLines | None" = None
               ) -> tuple[FrameArrays, ReadStats]:
    """Array reader = message reader (frames, counts, reasons, line numbers).

    With ``slow``: asserts that the array reader handed no line to the message parser.
    """
    s_arr, s_msg = ReadStats(), ReadStats()
    arr = _arrays(path, s_arr, chunk_bytes)
    if slow is not None:
        assert slow.lines == 0, f"{slow.lines} lines parsed one by one"
    _assert_same_frames(arr, FrameArrays.from_messages(_line_reader(path, s_msg)))
    assert s_arr == s_msg
    return arr, s_arr


class _CountSlowLines:
    """Wraps the message parser to count the lines the array reader hands to it."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.lines = 0
        inner = candump._candump_odd

        def counted(path, numbered, stats):  # type: ignore[no-untyped-def]
            numbered = list(numbered)
            self.lines += len(numbered)
            return inner(path, numbered, stats)

        monkeypatch.setattr(candump, "_candump_odd", counted)


# ---- timestamp texts -----------------------------------------------------------------------
@st.composite
def _layout_texts(draw: st.DrawFn) -> list[str]:
    """Timestamps of one digit layout (INT digits . FRAC digits): one column parse.

    Sizes from 1 to 20 integer and 1 to 26 fraction digits: below and above 2**53 as
    an integer (exact and not exact in float64), 10**FRAC beyond a float (> 22 digits).
    """
    ni = draw(st.integers(1, 20))
    nf = draw(st.integers(1, 26))
    n = draw(st.integers(1, 40))
    ints = draw(st.lists(st.integers(0, 10 ** ni - 1), min_size=n, max_size=n))
    fracs = draw(st.lists(st.integers(0, 10 ** nf - 1), min_size=n, max_size=n))
    return [f"{i:0{ni}d}.{f:0{nf}d}" for i, f in zip(ints, fracs)]


#: epoch seconds (2001 .. 2106) in ms/µs/ns/ps resolution; µs is candump's "%.6f"
_EPOCH_TEXTS = st.builds(lambda s, nf, f: f"{s}.{f % 10 ** nf:0{nf}d}",
                         st.integers(10 ** 9, 2 ** 32), st.sampled_from([3, 6, 6, 6, 9, 12]),
                         st.integers(0, 10 ** 12 - 1))
#: the integer N = 2**53 +- a little, with the point anywhere (the exactness boundary)
_BOUNDARY_TEXTS = st.builds(lambda n, k: f"{str(n)[:-k]}.{str(n)[-k:]}",
                            st.integers(2 ** 53 - 2000, 2 ** 53 + 2000), st.integers(1, 15))
#: small times in candump's form: INT + FRAC / 1e6 would be 1 ulp off for ~5 % of them
_SMALL_TEXTS = st.builds(lambda s: f"{s:.6f}", st.floats(0, 1000, allow_nan=False))
#: what float() may or may not take: signs, exponents, underscores, blanks, nan, no point
_ODD_TEXTS = st.text(alphabet="0123456789.._+-eEnaif ", min_size=0, max_size=24)

_TIMESTAMPS = st.one_of(_layout_texts(),
                        st.lists(st.one_of(_EPOCH_TEXTS, _BOUNDARY_TEXTS, _SMALL_TEXTS),
                                 min_size=1, max_size=40),
                        st.lists(st.one_of(_EPOCH_TEXTS, _ODD_TEXTS), min_size=1, max_size=20))


@settings(max_examples=300, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                 HealthCheck.data_too_large])
@given(texts=_TIMESTAMPS, id_digits=st.sampled_from([3, 8]), nbytes=st.integers(0, 8),
       seed=st.integers(0, 2 ** 32 - 1), chunk_bytes=st.sampled_from([48, 1 << 19]))
def test_timestamps_equal_float_of_text(tmp_path: Path, texts: list[str], id_digits: int,
                                        nbytes: int, seed: int, chunk_bytes: int) -> None:
    """Every timestamp the array reader returns is ``float(text)`` bit for bit, and every
    frame, bad-line count, reason and line number is the message reader's."""
    rng = np.random.default_rng(seed)
    lines = []
    for t in texts:
        can_id = int(rng.integers(0, 0x800 if id_digits == 3 else 0x20000000))
        data = bytes(rng.integers(0, 256, nbytes, dtype=np.uint8)).hex().upper()
        lines.append(f"({t}) can0 {can_id:0{id_digits}X}#{data}")
    path = tmp_path / "ts.log"
    path.write_text("\n".join(lines) + "\n")
    arr, stats = _check_log(path, chunk_bytes)
    want = []
    for t in texts:
        try:
            if " " not in t:   # a blank splits the line: malformed
                want.append(float(t))
        except ValueError:
            pass
    assert len(arr) == len(want) and stats.malformed == len(texts) - len(want)
    np.testing.assert_array_equal(arr.timestamp.view(np.int64),
                                  np.array(want, dtype=np.float64).view(np.int64))


BOUNDARY = ["9007199254740.991",     # N = 2**53 - 1: the last exact integer
            "9007199254740.992",     # 2**53
            "9007199254740.993",     # 2**53 + 1: not a float, float() rounds it
            "900719925474099.3",
            "3.794462",              # INT + FRAC / 1e6 is 1 ulp off here
            "0.1", "0.000001", "00000000000000000001.5",
            "1631416514.717133",     # candump epoch time: 16 digits
            "4294967295.999999",     # the last second of a uint32 epoch
            "1631416514.717133123",  # nanoseconds: 19 digits
            "1631416514.7171331234567890123456789",   # 10**28 is not a float
            "0.0000000000000000000000001",
            "18446744073709551616.5",                 # 2**64 + 0.5
            "99999999999999999999999999999.999999"]


@pytest.mark.parametrize("text", BOUNDARY)
def test_timestamp_boundaries_on_the_array_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                text: str) -> None:
    """Digit counts around the float64 limits: exact, and parsed by the column parser."""
    path = tmp_path / "b.log"
    path.write_text("".join(f"({text}) can0 1{k % 10}0#0102030405060708\n" for k in range(30)))
    arr, stats = _check_log(path, slow=_CountSlowLines(monkeypatch))
    assert stats.malformed == 0 and len(arr) == 30
    assert arr.timestamp.view(np.int64).tolist() == \
        [np.float64(float(text)).view(np.int64)] * 30


@pytest.mark.parametrize("t0, resolution", [(0.0, 6), (EPOCH, 6), (EPOCH, 9), (4.2e9, 3)])
def test_epoch_log_takes_the_array_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                        t0: float, resolution: int) -> None:
    """No regular line of a log with epoch times goes line by line (the 40x slow path)."""
    lines = [f"({t0 + k * 1e-3 + 1e-7 * (k % 7):.{resolution}f}) can0 {0x100 + k % 16:03X}#"
             f"{k & 0xFFFF:04X}0000{k % 251:02X}" for k in range(5000)]
    path = tmp_path / "epoch.log"
    path.write_text("\n".join(lines) + "\n")
    arr, _ = _check_log(path, chunk_bytes=1 << 14, slow=_CountSlowLines(monkeypatch))
    assert len(arr) == 5000
    assert arr.timestamp.view(np.int64).tolist() == \
        [np.float64(float(x[1:x.index(")")])).view(np.int64) for x in lines]


def test_real_candump_drive_log_on_the_array_path(realdata: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The real drive log (epoch times): every one of its 82,558 lines by the column parser,
    frames equal to the message reader's."""
    arr, stats = _check_log(realdata / "candump-drive" / "can_sample.log",
                            slow=_CountSlowLines(monkeypatch))
    assert stats.malformed == 0 and len(arr) == 82558
    assert arr.timestamp[0] == 1631416514.717133


# ---- any line ------------------------------------------------------------------------------
_HEX = "0123456789abcdefABCDEF"
_TS = st.one_of(_EPOCH_TEXTS, _SMALL_TEXTS, _BOUNDARY_TEXTS, _ODD_TEXTS)
_IDS = st.one_of(st.integers(0, 0x7FF).map("{:03X}".format),
                 st.integers(0, 0x1FFFFFFF).map("{:08X}".format),
                 st.sampled_from(["20000080", "2000008F", "A0000001", "7df", "1", "123456789"]),
                 st.text(alphabet=_HEX + "G ", min_size=0, max_size=9))
_PAYLOADS = st.one_of(
    st.binary(max_size=8).map(lambda b: b.hex().upper()),
    st.binary(max_size=8).map(bytes.hex),
    st.builds(lambda f, b: f"#{f}{b.hex()}", st.sampled_from("0123F"),   # CAN FD
              st.binary(max_size=64)),
    st.sampled_from(["R", "R0", "R8", "r", "R15"]),                          # remote
    st.text(alphabet=_HEX + "#RxZ ", max_size=20))                          # odd
_GOOD_LINES = st.builds(lambda t, iface, fid, data, tail: f"({t}) {iface} {fid}#{data}{tail}",
                        _TS, st.sampled_from(["can0", "vcan12", "c", "can\u00e9"]), _IDS,
                        _PAYLOADS, st.sampled_from(["", "", " R", " T", " T x", "  ", " "]))
_LINES = st.one_of(
    _GOOD_LINES, _GOOD_LINES, _GOOD_LINES,
    _GOOD_LINES.map(lambda x: x.replace(" ", "  ", 1)),                 # odd spacing
    _GOOD_LINES.map(lambda x: x.replace(" ", "\t")),
    st.builds(lambda x, k: x[:k], _GOOD_LINES, st.integers(0, 60)),    # truncated
    st.text(alphabet=st.characters(max_codepoint=0xFF, exclude_characters="\r\n"),
            max_size=40),                                               # garbage
    st.just(""), st.just("   "))


@settings(max_examples=300, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                 HealthCheck.data_too_large])
@given(lines=st.lists(_LINES, min_size=0, max_size=80),
       breaks=st.lists(st.sampled_from(["\n", "\n", "\n", "\r\n", "\r"]), min_size=1,
                       max_size=80),
       last_break=st.booleans(), chunk_bytes=st.sampled_from([1, 37, 200, 1 << 19]),
       repeat=st.integers(1, 30))
def test_any_lines_equal_messages(tmp_path: Path, lines: list[str], breaks: list[str],
                                  last_break: bool, chunk_bytes: int, repeat: int) -> None:
    """Any mix of regular, FD, remote, error, badly spaced, truncated, garbage and blank
    lines, LF/CRLF/CR line breaks, bytes beyond ASCII, any chunk size: the array reader's
    frames, malformed counts, reasons and line numbers are the message reader's."""
    lines = lines * repeat if len(lines) * repeat <= 400 else lines   # layouts of many rows
    text = "".join(x + breaks[k % len(breaks)] for k, x in enumerate(lines))
    if not last_break and text:
        text = text[:-1] if not text.endswith("\r\n") else text[:-2]
    path = tmp_path / "any.log"
    path.write_bytes(text.encode("latin-1"))
    _check_log(path, chunk_bytes)


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), rates=RATES,
       time_source=st.sampled_from(["timestamp", "tick"]), garbage=st.integers(0, 5),
       t0=st.sampled_from([1e6, 1631416514.0, 1631416514.717133, 4294967295.0]))
def test_epoch_log_arrays_equal_messages(tmp_path: Path, seed: int, rates: dict[str, float],
                                         time_source: str, garbage: int, t0: float) -> None:
    """``test_batch_equivalence.test_log_arrays_equal_messages`` with epoch times: a
    candump log through feed_log (array reader + batches) = read_log messages one by one."""
    frames = [m for m in _stream(seed, 200, rates, time_source == "tick", False)
              if math.isfinite(m.timestamp) and m.timestamp >= 0]
    for m in frames:
        m.timestamp += t0
    path = tmp_path / f"s{seed}.log"
    _write_candump(path, frames)
    truncate_lines(path, seed, garbage)
    _check_log(path)
    assert_feed_log_equals_messages(path, time_source)
