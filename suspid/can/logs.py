"""CAN log formats by file suffix, read tolerantly and written through python-can.

========  ==========================  =====================================================
suffix    format                      reader / writer
========  ==========================  =====================================================
``.log``  candump -L (SocketCAN)      own line parser (fast, bad lines counted) / python-can
``.asc``  Vector ASCII                python-can ``ASCReader`` (absolute time) / ``ASCWriter``
``.blf``  Vector binary logging       python-can ``BLFReader`` / ``BLFWriter``
``.trc``  PEAK trace                  python-can ``TRCReader`` / ``TRCWriter``
``.mf4``  ASAM MDF 4 (CANedge)        python-can ``MF4Reader`` / ``MF4Writer`` (asammdf)
========  ==========================  =====================================================

Suffixes are matched case-insensitively (CANedge writes ``.MF4``). Readers are iterators
of :class:`can.Message` that never stop on a bad line: an unparseable line is counted in
:class:`ReadStats` (and reported as rejected ``malformed`` by the decoder) and reading goes
on; a binary file cut short ends the iteration with ``ReadStats.truncated`` set. The
candump parser exists for speed: python-can's reader builds each payload byte by byte and
stops at the first bad line; ours uses ``bytearray.fromhex`` and reads ~2x faster.

Timestamps written equal the frames' ``timestamp`` to the format's resolution (1 µs for
``.log``/``.asc``/``.trc``; BLF stores nanoseconds); the ASC writer anchors the
``Begin Triggerblock`` date on the whole millisecond so that absolute times read back
exactly (python-can's would drop the sub-millisecond part of the first timestamp).
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Iterator, Optional

import can

from suspid.errors import InputError, UsageError

#: suffix -> human name, for messages and docs
FORMATS: dict[str, str] = {
    ".log": "candump -L",
    ".asc": "Vector ASC",
    ".blf": "Vector BLF",
    ".trc": "PEAK TRC",
    ".mf4": "ASAM MDF4",
}

_CAN_ERR_FLAG = 0x20000000
_CAN_EFF_FLAG = 0x80000000


def log_format(path: str | Path, option: str = "log") -> str:
    """Normalised suffix of a CAN log path.

    Raises
    ------
    UsageError
        For a suffix that is not a known CAN log format, naming the known ones.
    """
    suf = Path(path).suffix.lower()
    if suf not in FORMATS:
        known = ", ".join(f"{s} ({n})" for s, n in FORMATS.items())
        raise UsageError(f"{path}: unknown {option} format {Path(path).suffix or '(no suffix)'!r}; "
                         f"expected one of {known}")
    return suf


def is_can_log(path: str | Path) -> bool:
    """``True`` if the path's suffix names a CAN log format (case-insensitive)."""
    return Path(path).suffix.lower() in FORMATS


@dataclass
class ReadStats:
    """What a tolerant reader skipped.

    Attributes
    ----------
    frames : int
        Frames yielded.
    malformed : int
        Lines (or records) that could not be parsed and were skipped.
    truncated : bool
        A binary file ended in the middle of a record.
    examples : list of str
        The first few problems, ``file:line: reason``.
    """

    frames: int = 0
    malformed: int = 0
    truncated: bool = False
    examples: list[str] = field(default_factory=list)

    def bad(self, where: str, reason: str) -> None:
        """Count one skipped line/record and keep the first five reasons."""
        self.malformed += 1
        if len(self.examples) < 5:
            self.examples.append(f"{where}: {' '.join(reason.split())[:120]}")


def _compile_fast_message() -> "object":
    """A constructor of classic data frames that skips ``can.Message.__init__``'s checks.

    ``Message.__init__`` validates and converts every argument (~1.2 µs); a log parser
    that already has a well-formed ``bytearray`` only needs the slots filled (~0.4 µs).
    The slot list comes from the installed python-can, every other slot gets the value
    of a default-constructed message, so the objects are indistinguishable.
    """
    template = can.Message()
    given = {"timestamp", "arbitration_id", "is_extended_id", "data", "dlc", "channel", "is_rx"}
    ns: dict[str, object] = {"_new": can.Message.__new__, "_M": can.Message}
    lines = ["def _fast_message(timestamp, arbitration_id, is_extended_id, data, channel, is_rx):",
             "    m = _new(_M)",
             "    m.timestamp = timestamp",
             "    m.arbitration_id = arbitration_id",
             "    m.is_extended_id = is_extended_id",
             "    m.data = data",
             "    m.dlc = len(data)",
             "    m.channel = channel",
             "    m.is_rx = is_rx"]
    for slot in can.Message.__slots__:
        if slot in given or slot.startswith("__"):
            continue
        ns[f"_d_{slot}"] = getattr(template, slot)
        lines.append(f"    m.{slot} = _d_{slot}")
    lines.append("    return m")
    exec("\n".join(lines), ns)  # noqa: S102 - generated from python-can's slot names
    return ns["_fast_message"]


_fast_message = _compile_fast_message()


def _candump_special(ts: float, can_id: int, ext: bool, data_s: str, channel: str,
                     is_rx: bool) -> can.Message:
    """The rare candump frame kinds: CAN FD ``ID##<flags><data>`` and remote ``ID#R[len]``."""
    if data_s[:1] == "#":
        flags = int(data_s[1], 16)
        return can.Message(timestamp=ts, arbitration_id=can_id & 0x1FFFFFFF, is_extended_id=ext,
                           is_fd=True, bitrate_switch=bool(flags & 1),
                           error_state_indicator=bool(flags & 2),
                           data=bytearray.fromhex(data_s[2:]), channel=channel, is_rx=is_rx,
                           check=False)
    if data_s[:1] in ("R", "r"):
        dlc = int(data_s[1:]) if len(data_s) > 1 else 0
        return can.Message(timestamp=ts, arbitration_id=can_id & 0x1FFFFFFF, is_extended_id=ext,
                           is_remote_frame=True, dlc=dlc, channel=channel, is_rx=is_rx,
                           check=False)
    raise ValueError(f"payload {data_s[:24]!r} is not hex")


def _read_candump(path: Path, stats: ReadStats) -> Iterator[can.Message]:
    """candump -L lines ``(ts) iface ID#DATA`` (also ``ID##F DATA`` FD, ``ID#R`` remote).

    The common line takes one ``split``, one ``partition`` and three conversions; the
    rare kinds (FD, remote, error frames) and bad lines leave the fast path through the
    exception of ``bytearray.fromhex``.
    """
    fromhex = bytearray.fromhex
    fast = _fast_message
    err_flag = _CAN_ERR_FLAG
    try:
        fh = path.open("r", encoding="ascii", errors="replace")
    except OSError as exc:
        raise InputError(f"{path}: cannot open CAN log: {exc.strerror}") from None
    frames = 0
    try:
        with fh:
            for lineno, line in enumerate(fh, 1):
                parts = line.split()
                try:
                    ts_s = parts[0]
                    if ts_s[0] != "(" or ts_s[-1] != ")":
                        if not parts:
                            continue
                        raise ValueError(f"expected '(seconds)' first, got {ts_s[:24]!r}")
                    ts = float(ts_s[1:-1])
                    id_s, sep, data_s = parts[2].partition("#")
                    if not sep:
                        raise ValueError(f"expected ID#DATA, got {parts[2][:24]!r}")
                    can_id = int(id_s, 16)
                    ext = len(id_s) > 3
                    is_rx = len(parts) < 4 or parts[3] != "T"
                    try:
                        payload = fromhex(data_s)
                    except ValueError:
                        msg = _candump_special(ts, can_id, ext, data_s, parts[1], is_rx)
                        frames += 1
                        yield msg
                        continue
                    if len(payload) > 8:
                        raise ValueError(f"{len(payload)} data bytes in a classic CAN frame")
                except IndexError:
                    if parts:
                        stats.bad(f"{path}:{lineno}", "expected '(seconds) interface ID#DATA'")
                    continue
                except ValueError as exc:
                    stats.bad(f"{path}:{lineno}", str(exc) or "unparseable line")
                    continue
                frames += 1
                if can_id & err_flag and ext:
                    yield can.Message(timestamp=ts, is_error_frame=True, channel=parts[1],
                                      check=False)
                    continue
                yield fast(ts, can_id, ext, payload, parts[1], is_rx)  # type: ignore[operator]
    finally:
        stats.frames += frames


class _LineCounter:
    """File wrapper counting the lines a python-can text reader consumes."""

    def __init__(self, fh) -> None:  # type: ignore[no-untyped-def]
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


def _read_text_resumable(path: Path, reader: can.io.generic.MessageReader,
                         stats: ReadStats) -> Iterator[can.Message]:
    """Run a python-can text reader, restarting it after a line that raises.

    python-can's ASC/TRC readers parse the header inside ``__iter__`` and die on the
    first bad data line. The reader keeps its state (base, start time, version) in
    ``self``; after an exception the file is positioned after the bad line, so a new
    ``__iter__`` with the header step disabled resumes exactly there.
    """
    counter = _LineCounter(reader.file)
    reader.file = counter  # type: ignore[assignment]
    first = True
    while True:
        try:
            for msg in type(reader).__iter__(reader):
                stats.frames += 1
                yield msg
            return
        except (ValueError, IndexError, KeyError, TypeError) as exc:
            stats.bad(f"{path}:{counter.lineno}", f"{type(exc).__name__}: {exc}")
        if first:
            first = False
            # header already parsed (state kept in the reader): do not consume lines again
            reader._extract_header = lambda *a, **k: None  # type: ignore[method-assign]


def _read_binary(path: Path, reader: can.io.generic.MessageReader,
                 stats: ReadStats) -> Iterator[can.Message]:
    try:
        for msg in reader:
            stats.frames += 1
            yield msg
    except Exception as exc:  # a damaged binary log: keep what was read
        stats.truncated = True
        stats.bad(f"{path}: after frame {stats.frames}", f"{type(exc).__name__}: {exc}")
    finally:
        try:
            reader.stop()
        except Exception:  # pragma: no cover - closing a broken reader
            pass


def read_log(path: str | Path, stats: Optional[ReadStats] = None) -> Iterator[can.Message]:
    """Iterate over the frames of a CAN log (format by suffix), skipping bad lines.

    Parameters
    ----------
    path : str or Path
        ``.log``, ``.asc``, ``.blf``, ``.trc`` or ``.mf4`` (any case).
    stats : ReadStats, optional
        Filled with the number of frames read and lines skipped.

    Yields
    ------
    can.Message
        In file order, with the log's timestamps (s; absolute where the format stores them).

    Raises
    ------
    InputError
        Missing or unreadable file, or a file whose header cannot be read.
    UsageError
        Unknown suffix.
    """
    p = Path(path)
    suf = log_format(p, "CAN log")
    if not p.is_file():
        raise InputError(f"{p}: no such CAN log file")
    st = stats if stats is not None else ReadStats()
    if suf == ".log":
        return _read_candump(p, st)
    try:
        if suf == ".asc":
            reader = can.ASCReader(str(p), relative_timestamp=False)
            return _read_text_resumable(p, reader, st)
        if suf == ".trc":
            # the TRC reader logs a warning per line it cannot parse; we count them instead
            logging.getLogger("can.io.trc").setLevel(logging.ERROR)
            reader = can.TRCReader(str(p))
            return _read_text_resumable(p, reader, st)
        if suf == ".blf":
            reader = can.BLFReader(str(p))
        else:
            reader = can.MF4Reader(str(p))
    except ImportError as exc:  # asammdf missing
        raise InputError(f"{p}: reading {FORMATS[suf]} needs an extra package: {exc}") from None
    except Exception as exc:
        raise InputError(f"{p}: not a readable {FORMATS[suf]} file: {type(exc).__name__}: "
                         f"{' '.join(str(exc).split())[:160]}") from None
    return _read_binary(p, reader, st)


class _ASCWriter(can.ASCWriter):
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


def open_log_writer(path: str | Path) -> can.io.generic.MessageWriter:
    """A python-can writer for the log format of ``path`` (use as a context manager).

    Raises
    ------
    UsageError
        Unknown suffix.
    InputError
        The file cannot be created.
    """
    p = Path(path)
    suf = log_format(p, "output log")
    try:
        if suf == ".log":
            return can.CanutilsLogWriter(str(p), channel="can0")
        if suf == ".asc":
            return _ASCWriter(str(p))
        if suf == ".blf":
            return can.BLFWriter(str(p))
        if suf == ".trc":
            return can.TRCWriter(str(p))
        return can.MF4Writer(str(p))
    except ImportError as exc:
        raise InputError(f"{p}: writing {FORMATS[suf]} needs an extra package: {exc}") from None
    except OSError as exc:
        raise InputError(f"{p}: cannot create log file: {exc.strerror or exc}") from None
