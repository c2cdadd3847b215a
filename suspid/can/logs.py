"""CAN log formats by file suffix (``.log`` candump, ``.asc``, ``.blf``, ``.trc``, ``.mf4``),
read tolerantly and written through python-can (docs/can.md lists readers and writers).

The formats are one table, :data:`LOG_FORMATS` (suffix, case-insensitive -> :class:`LogFormat`),
which :func:`read_log`, :func:`read_log_arrays` and :func:`open_log_writer` dispatch on; an
unknown suffix is a one-line :class:`~suspid.errors.UsageError` listing the known ones.

Readers never stop on a bad line: it is counted in :class:`ReadStats` and reading goes on; a
binary file cut short ends the iteration with ``ReadStats.truncated`` set. Timestamps written
equal the frames' ``timestamp`` to the format's resolution (1 µs; BLF ns).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Callable, Iterable, Iterator, Optional

import can

from suspid.can.candump import candump_batches, read_candump, read_candump_arrays
from suspid.can.formats import FORMATS, GZIP_READ, log_suffix
from suspid.can.frames import (NO_CHANNEL, FrameArrays, LabelledFrames, ReadStats, channel_label,
                               channel_wanted, describe_channels, select_arrays, select_messages)
from suspid.can.pycan_logs import ASCWriter, BLFWriter, read_asc, read_blf, read_mf4, read_trc
from suspid.errors import InputError, UsageError

__all__ = ["FORMATS", "GZIP_READ", "LOG_FORMATS", "NO_CHANNEL", "FrameArrays", "LabelledFrames",
           "LogFormat", "ReadStats", "channel_label", "channel_wanted", "describe_channels",
           "first_timestamp", "is_can_log", "log_format", "open_log_writer", "read_candump_arrays",
           "read_log", "read_log_arrays"]


def log_format(path: str | Path, option: str = "log", compressed: bool = True) -> str:
    """Normalised suffix of a CAN log path (``.asc`` for ``F.asc.gz`` too, unless
    ``compressed`` is false); a :class:`UsageError` naming the known ones for another."""
    suf = log_suffix(path, compressed)
    if suf not in LOG_FORMATS:
        known = ", ".join(f"{s} ({f.name})" for s, f in LOG_FORMATS.items())
        gz = f", {' '.join(f'{s}.gz' for s in GZIP_READ)} (compressed)" if compressed else ""
        raise UsageError(f"{path}: unknown {option} format {Path(path).suffix or '(no suffix)'!r}; "
                         f"expected one of {known}{gz}")
    return suf


def _open_log(path: str | Path, stats: Optional["ReadStats"]) -> tuple[Path, str, "ReadStats"]:
    """Path, format suffix and the stats to fill of a log about to be read (checks both)."""
    p = Path(path)
    suf = log_format(p, "CAN log")
    if not p.is_file():
        raise InputError(f"{p}: no such CAN log file")
    return p, suf, (stats if stats is not None else ReadStats())


def is_can_log(path: str | Path) -> bool:
    """``True`` if the path's suffix names a CAN log format of :data:`LOG_FORMATS`."""
    return log_suffix(path) in LOG_FORMATS


def read_log_arrays(path: str | Path, stats: Optional[ReadStats] = None, *,
                    chunk: int = 65536, channel: Optional[str] = None) -> Iterator[FrameArrays]:
    """The frames of a CAN log (format by suffix) as :class:`FrameArrays` batches.

    candump -L is parsed as arrays; the other formats are read as messages and converted
    ``chunk`` frames at a time. Same checks, errors, ``channel`` and stats as :func:`read_log`.
    """
    p, suf, st = _open_log(path, stats)
    batches = LOG_FORMATS[suf].read_arrays
    if batches is not None:
        return select_arrays(p, suf, batches(p, st), st, channel)
    return _message_batches(read_log(p, st, channel=channel), chunk)


def _message_batches(messages: Iterable[can.Message], chunk: int) -> Iterator[FrameArrays]:
    batch: list[can.Message] = []
    for msg in messages:
        batch.append(msg)
        if len(batch) >= chunk:
            yield FrameArrays.from_messages(batch)
            batch = []
    if batch:
        yield FrameArrays.from_messages(batch)


def first_timestamp(path: str | Path) -> float | None:
    """The timestamp (s; epoch where the format stores absolute times) of a log's first frame
    on the logger's clock, ``None`` for a log without a readable frame."""
    for msg in read_log(path):
        return float(msg.timestamp)
    return None


def read_log(path: str | Path, stats: Optional[ReadStats] = None, *,
             channel: Optional[str] = None) -> Iterator[can.Message]:
    """The frames of a CAN log (format by suffix of :data:`LOG_FORMATS`) in file order, bad
    lines skipped; ``stats`` filled with the frames read, lines skipped and frames per bus
    channel. With ``channel`` (:func:`channel_wanted`: ``"1"``, ``"CAN1"``, ``"can1"`` for
    candump) only its frames, the others counted in ``stats.other_channel``.

    Raises :class:`InputError` for a missing or unreadable file or header, :class:`UsageError`
    for an unknown suffix and, at the end of the log, a ``channel`` that no frame has.
    """
    p, suf, st = _open_log(path, stats)
    fmt = LOG_FORMATS[suf]
    try:
        return select_messages(p, suf, fmt.read(p, st), st, channel)
    except InputError:
        raise
    except ImportError as exc:  # asammdf missing
        raise InputError(f"{p}: reading {fmt.name} needs an extra package: {exc}") from None
    except Exception as exc:
        raise InputError(f"{p}: not a readable {fmt.name} file: {type(exc).__name__}: "
                         f"{' '.join(str(exc).split())[:160]}") from None


def open_log_writer(path: str | Path) -> can.io.generic.MessageWriter:
    """A python-can writer for the log format of ``path`` (use as a context manager); raises
    :class:`UsageError` for an unknown suffix, :class:`InputError` if it cannot be created."""
    p = Path(path)
    fmt = LOG_FORMATS[log_format(p, "output log", compressed=False)]
    try:
        return fmt.write(str(p))
    except ImportError as exc:
        raise InputError(f"{p}: writing {fmt.name} needs an extra package: {exc}") from None
    except OSError as exc:
        raise InputError(f"{p}: cannot create log file: {exc.strerror or exc}") from None


@dataclass(frozen=True)
class LogFormat:
    """One CAN log format of :data:`LOG_FORMATS`.

    ``read(path, stats)`` yields messages, tolerantly; ``write(path)`` is a python-can writer;
    ``read_arrays(path, stats)`` yields :data:`LabelledFrames` where the format has a batch
    parser (``None``: the messages of ``read`` are converted).
    """

    name: str
    read: Callable[[Path, ReadStats], Iterator[can.Message]]
    write: Callable[[str], can.io.generic.MessageWriter]
    read_arrays: Optional[Callable[[Path, ReadStats], Iterator[LabelledFrames]]] = None


#: suffix (lower case) -> format: the one table choosing readers and writers (use
#: :func:`is_can_log` or :func:`log_format` rather than a list of suffixes of your own)
LOG_FORMATS: dict[str, LogFormat] = {
    ".log": LogFormat(FORMATS[".log"], read_candump, partial(can.CanutilsLogWriter, channel="can0"),
                      candump_batches),
    ".asc": LogFormat(FORMATS[".asc"], read_asc, ASCWriter),
    ".blf": LogFormat(FORMATS[".blf"], read_blf, BLFWriter),
    ".trc": LogFormat(FORMATS[".trc"], read_trc, can.TRCWriter),
    ".mf4": LogFormat(FORMATS[".mf4"], read_mf4, can.MF4Writer),
}
