"""ASC, TRC, BLF and MF4 logs through python-can: tolerant readers and writers that read back.

The readers go on after a bad line (counted in :class:`~suspid.can.frames.ReadStats`) and
keep the frames before a damaged or cut-short part of a binary or compressed file; the
writers fix python-can's ASC trigger-block date and BLF start time so that times read back
as written.
"""
from __future__ import annotations

import contextlib
import gzip
import io
import locale
import logging
import math
import re
import struct
from datetime import datetime
from decimal import Decimal
from pathlib import Path
from typing import Callable, Iterator, Optional, TextIO, cast

import can

from suspid.can.damage import blf_damage, mdf_damage
from suspid.can.frames import ReadStats
from suspid.errors import InputError

class _LineCounter:
    """File wrapper counting the lines a python-can text reader consumes."""

    def __init__(self, fh: TextIO) -> None:
        self.fh = fh
        self.lineno = 0

    def __iter__(self) -> "_LineCounter":
        return self

    def __next__(self) -> str:
        line = next(self.fh)
        self.lineno += 1
        return line

    def __getattr__(self, name: str) -> object:
        return getattr(self.fh, name)


#: ASC header line declaring relative timestamps
_ASC_RELATIVE = re.compile(r"\s*base\s+(?:hex|dec)\s+timestamps\s+relative\b", re.IGNORECASE)
#: ASC trigger block start (the time origin of the events after it)
_ASC_TRIGGER = re.compile(r"\s*begin\s+triggerblock\b", re.IGNORECASE)
#: an ASC event line: its leading time (s), as python-can's reader recognises it
_ASC_EVENT = re.compile(r"(\s*)(\d+\.\d+)(?=\s)")


class _AscLines(_LineCounter):
    """ASC lines counted, with relative event times made absolute (from the trigger block).

    An ASC file whose header says ``base hex  timestamps relative`` (a CANalyzer/CANoe
    logging option) stamps every event with the time since the previous event; python-can's
    reader reads every time as absolute (it records the header's mode and ignores it), so
    such a log came out as frames about one interval after the trigger block, nearly all
    rejected as going back in time. Here every timestamped line -- frames and the events
    python-can skips (``Start of measurement``, status, comments with a time) alike -- adds
    its time to a running sum kept as an exact decimal, restarted at each ``Begin
    Triggerblock``, and the line is handed on with the sum, so the reader sees the log as if
    it had been written with ``timestamps absolute``.
    """

    def __init__(self, fh: TextIO) -> None:
        super().__init__(fh)
        self.relative = False
        self.elapsed = Decimal(0)

    def __next__(self) -> str:
        line = next(self.fh)
        self.lineno += 1
        if self.relative:
            m = _ASC_EVENT.match(line)
            if m is not None:
                self.elapsed += Decimal(m.group(2))
                return f"{m.group(1)}{self.elapsed:f}{line[m.end():]}"
            if _ASC_TRIGGER.match(line):
                self.elapsed = Decimal(0)
        elif "elative" in line and _ASC_RELATIVE.match(line):
            self.relative = True
        return line


def _open_text(path: Path, lines: type[_LineCounter] = _LineCounter) -> _LineCounter:
    """A text log opened as python-can would open it, its lines counted (by ``lines``)."""
    try:
        if path.suffix.lower() == ".gz":
            fh = cast(TextIO, gzip.open(path, "rt", encoding=locale.getpreferredencoding(False)))
        else:
            fh = path.open("r", encoding=locale.getpreferredencoding(False))
    except OSError as exc:
        raise InputError(f"{path}: cannot open CAN log: {exc.strerror}") from None
    return lines(fh)


def _skip_header(*_args: object, **_kwargs: object) -> None:
    """Stands in for a python-can text reader's header parser once the header is read."""
    return None


def _read_text_resumable(path: Path, reader: can.ASCReader | can.TRCReader,
                         counter: _LineCounter, stats: ReadStats) -> Iterator[can.Message]:
    """Run a python-can text reader on ``counter``, restarting it after a line that raises.

    python-can's ASC/TRC readers parse the header inside ``__iter__`` and die on the
    first bad data line. The reader keeps its state (base, start time, version) in
    ``self``; after an exception the file is positioned after the bad line, so a new
    ``__iter__`` with the header step disabled resumes exactly there. python-can has no
    public way to resume a reader or to skip its header, hence the instance patch of
    ``_extract_header`` below (tested in ``tests/can/test_logs.py`` on damaged logs).
    """
    first = True
    while True:
        try:
            for msg in reader:   # a new __iter__ each time (a generator method)
                stats.frames += 1
                yield msg
            return
        except (EOFError, gzip.BadGzipFile) as exc:  # a .gz cut short or not gzip at all
            if stats.frames == 0:
                raise InputError(f"{path}: not a readable gzip file after line {counter.lineno} "
                                 f"({exc})") from None
            # cut short: the lines before the cut are the log's; keep them and name the damage
            stats.damaged(path, f"the compressed stream ends after line {counter.lineno} "
                                f"({exc}): the file is cut short; {stats.frames} frames read "
                                "before it are used")
            return
        except (ValueError, IndexError, KeyError, TypeError) as exc:
            stats.bad(f"{path}:{counter.lineno}", f"{type(exc).__name__}: {exc}")
        if first:
            first = False
            # header already parsed (state kept in the reader): do not consume lines again
            # no public API (see above); ASC's parser returns None, TRC's the first data line
            reader._extract_header = _skip_header  # type: ignore[method-assign, assignment]


def read_asc(path: Path, stats: ReadStats) -> Iterator[can.Message]:
    counter = _open_text(path, _AscLines)
    try:
        reader = can.ASCReader(cast(TextIO, counter), relative_timestamp=False)   # duck-typed
    except BaseException:
        counter.fh.close()
        raise
    return _read_text_resumable(path, reader, counter, stats)


def read_trc(path: Path, stats: ReadStats) -> Iterator[can.Message]:
    # the TRC reader logs a warning per line it cannot parse; we count them instead
    logging.getLogger("can.io.trc").setLevel(logging.ERROR)
    counter = _open_text(path)
    try:
        reader = can.TRCReader(cast(TextIO, counter))   # duck-typed text stream
    except BaseException:
        counter.fh.close()
        raise
    return _read_text_resumable(path, reader, counter, stats)


#: a Vector BLF file begins with this signature and a header of ``BLF_HEADER`` bytes
BLF_SIGNATURE = b"LOGG"
BLF_HEADER = 144


def read_blf(path: Path, stats: ReadStats) -> Iterator[can.Message]:
    with open(path, "rb") as fh:
        head = fh.read(BLF_HEADER)
    if len(head) < BLF_HEADER or not head.startswith(BLF_SIGNATURE):
        if not head:
            what = "an empty file"
        elif len(head) < BLF_HEADER:
            what = f"{len(head)} bytes beginning {head[:4]!r}"
        else:
            what = f"a file beginning {head[:4]!r}"
        raise InputError(f"{path}: not a Vector BLF file: expected the signature "
                         f"{BLF_SIGNATURE!r} and a {BLF_HEADER}-byte header, got {what}")
    return _read_binary(path, can.BLFReader(str(path)), stats, lambda: blf_damage(path))


def _quiet_mdf4_del(original: Callable[[object], None]) -> Callable[[object], None]:
    """``MDF4.__del__`` that skips an object whose construction failed before it opened
    the file (asammdf's own ``__del__`` then raises ``AttributeError: _file``, which Python
    prints as 8 lines of "Exception ignored in" after our one-line error)."""
    def __del__(self: object) -> None:
        if hasattr(self, "_file"):
            original(self)
    __del__.suspid_guard = True  # type: ignore[attr-defined]
    return __del__


def _guard_mdf4_del() -> None:
    """Install :func:`_quiet_mdf4_del` on asammdf's ``MDF4`` (once; python-can imports it
    as ``can.io.mf4.MDF4``, ``None`` without asammdf)."""
    mdf4 = getattr(can.io.mf4, "MDF4", None)
    if mdf4 is not None and not getattr(mdf4.__del__, "suspid_guard", False):
        mdf4.__del__ = _quiet_mdf4_del(mdf4.__del__)


def _quiet_asammdf(record: logging.LogRecord) -> bool:
    """Drop asammdf's own log records (a traceback of a damaged file: named by us)."""
    return False


def read_mf4(path: Path, stats: ReadStats) -> Iterator[can.Message]:
    """python-can's MF4 reader; a file cut short inside its records is read up to the last
    whole record (:func:`~suspid.can.damage.mdf_damage`), a damaged structure is an error
    naming the byte."""
    _guard_mdf4_del()
    damage = mdf_damage(path)
    source: str | io.BytesIO = str(path)
    if damage is not None and damage.whole_to:
        with open(path, "rb") as fh:   # asammdf fails on the record cut short: leave it out
            source = io.BytesIO(fh.read(damage.whole_to))
    asammdf_log = logging.getLogger("asammdf")
    asammdf_log.addFilter(_quiet_asammdf)
    try:
        # asammdf print()s the traceback of what it could not finalise to stdout, where the
        # JSON result goes; the damage is named by us
        with contextlib.redirect_stdout(io.StringIO()):
            reader = can.MF4Reader(source)
    except (ValueError, OSError, struct.error, KeyError, IndexError) as exc:
        if damage is None:
            raise
        raise InputError(f"{path}: damaged MF4 file: {damage.what}; no frame can be read "
                         "(asammdf, which python-can's MF4 reader uses: "
                         f"{type(exc).__name__}: {' '.join(str(exc).split())[:80]})") from None
    finally:
        asammdf_log.removeFilter(_quiet_asammdf)
    return _read_binary(path, reader, stats, lambda: damage.what if damage else None)


def _read_binary(path: Path, reader: can.io.generic.MessageReader, stats: ReadStats,
                 damage: Callable[[], str | None]) -> Iterator[can.Message]:
    """The frames of a python-can binary reader; a damaged file ends the read with the frames
    read so far and the damage named (``damage()``, else the reader's exception)."""
    failed = ""
    try:
        for msg in reader:
            stats.frames += 1
            yield msg
    except Exception as exc:  # a damaged binary log: keep what was read
        failed = f"the reader stopped after frame {stats.frames}: {type(exc).__name__}: " \
                 f"{' '.join(str(exc).split())[:80]}"
    finally:
        try:
            reader.stop()
        except Exception:  # pragma: no cover - closing a broken reader
            pass
    found = damage()
    if found is not None:
        stats.damaged(path, f"{found}; {stats.frames} frames read before it are used")
    elif failed:
        stats.damaged(path, failed)


class ASCWriter(can.ASCWriter):
    """ASCWriter whose trigger-block date is the first timestamp floored to the millisecond.

    ASC stores times relative to the ``Begin Triggerblock`` date, which has millisecond
    resolution; python-can makes the times relative to the exact first timestamp and so
    loses its sub-millisecond part on reading back absolute times.
    """

    def log_event(self, message: str, timestamp: Optional[float] = None) -> None:
        if not message:
            return
        if not self.header_written:
            first = timestamp or 0.0
            self.started = math.floor(first * 1000.0) / 1000.0
            self.last_timestamp = first
            start_time = datetime.fromtimestamp(self.started)
            self.file.write(f"Begin Triggerblock {self._format_header_datetime(start_time)}\n")
            self.header_written = True
            self.file.write(self.FORMAT_EVENT.format(timestamp=0.0, message="Start of measurement"))
        if timestamp is None:
            timestamp = self.last_timestamp
        if timestamp >= self.started:
            timestamp -= self.started
        self.file.write(self.FORMAT_EVENT.format(timestamp=timestamp, message=message))

    def _format_header_datetime(self, dt: datetime) -> str:
        # python-can writes the milliseconds unpadded ("00:00:01.5" for 5 ms), which its
        # reader then parses as 500 ms; always write three digits
        return dt.strftime(f"%a %b %d %H:%M:%S.{dt.microsecond // 1000:03d} %Y")


#: python-can's BLF writer stores a start time below this (1990-01-01, epoch s) as no date
#: (``timestamp_to_systemtime``), which its reader then takes as 0
BLF_DATED_FROM = 631152000.0


class BLFWriter(can.BLFWriter):
    """BLFWriter whose times read back as written when they are not epoch times.

    BLF stores each frame's time as unsigned nanoseconds after the file's start date.
    python-can takes the first frame's time as the start and writes it as a date only from
    1990 on; below that (a CSV's ``t`` from 0.5 s, say) it writes no date, which its reader
    takes as 0, so every time read back was short by the first one (0.5 s). Such times are
    stored here after a start of 0, so they read back as themselves; a negative time cannot
    be stored at all (python-can wrote it as the start) and is an error.
    """

    def _add_object(self, obj_type: int, data: bytes, timestamp: Optional[float] = None) -> None:
        if self.start_timestamp is None and timestamp is not None \
                and timestamp < BLF_DATED_FROM:
            self.start_timestamp = 0.0
        if timestamp is not None and timestamp < 0.0:
            raise InputError(f"{getattr(self.file, 'name', 'BLF log')}: a BLF log stores times "
                             f"from 0 s on, got a frame at {timestamp!r} s (shift the times, "
                             "e.g. with --t0)")
        super()._add_object(obj_type, data, timestamp)

