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
    """ASC lines counted, with relative event times made absolute.

    python-can reads the times of a ``timestamps relative`` ASC as absolute. Here every
    timed line (frames and the events python-can skips) adds its time to an exact decimal
    sum, restarted at each ``Begin Triggerblock``, and is handed on with the sum.
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


def _read_text_resumable(path: Path, reader: can.ASCReader | can.TRCReader,
                         counter: _LineCounter, stats: ReadStats) -> Iterator[can.Message]:
    """Run a python-can text reader on ``counter``, restarting it after a line that raises.

    python-can's ASC/TRC readers parse the header inside ``__iter__`` and die on the first
    bad line; their state stays in ``self`` and the file is positioned after the bad line,
    so a new ``__iter__`` with the header step patched out (no public API) resumes there.
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
            # cut short: keep the lines before the cut and name the damage
            stats.damaged(path, f"the compressed stream ends after line {counter.lineno} "
                                f"({exc}): the file is cut short; {stats.frames} frames read "
                                "before it are used")
            return
        except (ValueError, IndexError, KeyError, TypeError) as exc:
            stats.bad(f"{path}:{counter.lineno}", f"{type(exc).__name__}: {exc}")
        if first:
            first = False
            # header already parsed: do not consume lines again
            reader._extract_header = lambda *_a, **_k: None  # type: ignore[method-assign]


def _read_text(path: Path, stats: ReadStats, make: Callable[[TextIO], can.ASCReader | can.TRCReader],
               lines: type[_LineCounter] = _LineCounter) -> Iterator[can.Message]:
    """A python-can text reader (``make``) on a log opened as python-can would open it, its
    lines counted (by ``lines``), run by :func:`_read_text_resumable`."""
    try:
        if path.suffix.lower() == ".gz":
            fh = cast(TextIO, gzip.open(path, "rt", encoding=locale.getpreferredencoding(False)))
        else:
            fh = path.open("r", encoding=locale.getpreferredencoding(False))
    except OSError as exc:
        raise InputError(f"{path}: cannot open CAN log: {exc.strerror}") from None
    counter = lines(fh)
    try:
        reader = make(cast(TextIO, counter))   # duck-typed text stream
    except BaseException:
        counter.fh.close()
        raise
    return _read_text_resumable(path, reader, counter, stats)


def read_asc(path: Path, stats: ReadStats) -> Iterator[can.Message]:
    return _read_text(path, stats, lambda fh: can.ASCReader(fh, relative_timestamp=False), _AscLines)


def read_trc(path: Path, stats: ReadStats) -> Iterator[can.Message]:
    # the TRC reader logs a warning per line it cannot parse; we count them instead
    logging.getLogger("can.io.trc").setLevel(logging.ERROR)
    return _read_text(path, stats, can.TRCReader)


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


def _guard_mdf4_del() -> None:
    """Make asammdf's ``MDF4.__del__`` (once, if installed) skip an object whose construction
    failed before it opened the file (asammdf's own would print 8 lines of "Exception ignored
    in")."""
    mdf4 = getattr(can.io.mf4, "MDF4", None)
    if mdf4 is None or getattr(mdf4.__del__, "suspid_guard", False):
        return
    original = mdf4.__del__

    def __del__(self: object) -> None:
        if hasattr(self, "_file"):
            original(self)
    __del__.suspid_guard = True  # type: ignore[attr-defined]
    mdf4.__del__ = __del__


def _quiet_asammdf(record: logging.LogRecord) -> bool:
    """Drop asammdf's own log records (a traceback of a damaged file: named by us)."""
    return False


def read_mf4(path: Path, stats: ReadStats) -> Iterator[can.Message]:
    """python-can's MF4 reader; a file cut inside its records is read up to the last whole
    record, a damaged structure is an error naming the byte."""
    _guard_mdf4_del()
    damage = mdf_damage(path)
    source: str | io.BytesIO = str(path)
    if damage is not None and damage.whole_to:
        with open(path, "rb") as fh:   # asammdf fails on the record cut short: leave it out
            source = io.BytesIO(fh.read(damage.whole_to))
    asammdf_log = logging.getLogger("asammdf")
    asammdf_log.addFilter(_quiet_asammdf)
    try:
        # asammdf prints tracebacks to stdout, where the JSON result goes
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
    """ASCWriter whose trigger-block date (ms resolution) is the first timestamp floored to
    the millisecond, so that absolute times read back exactly."""

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
        # python-can writes the milliseconds unpadded, which its reader misreads
        return dt.strftime(f"%a %b %d %H:%M:%S.{dt.microsecond // 1000:03d} %Y")


#: python-can's BLF writer stores a start time below this (1990-01-01, epoch s) as no date
#: (``timestamp_to_systemtime``), which its reader then takes as 0
BLF_DATED_FROM = 631152000.0


class BLFWriter(can.BLFWriter):
    """BLFWriter whose times read back as written when they are not epoch times.

    python-can writes no start date before 1990 (its reader then takes 0) while counting the
    times from the first frame; such times are stored after a start of 0. A negative time
    cannot be stored (BLF times are unsigned) and is an error.
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

