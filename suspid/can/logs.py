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

The formats are one table, :data:`LOG_FORMATS` (suffix -> :class:`LogFormat`: name, reader,
writer, batch reader), which :func:`read_log`, :func:`read_log_arrays` and
:func:`open_log_writer` dispatch on; :func:`is_can_log` and :func:`log_format` answer
"is this a CAN log" for other modules, and an unknown suffix is a one-line
:class:`~suspid.errors.UsageError` listing the known ones.

Suffixes are matched case-insensitively (CANedge writes ``.MF4``). Readers are iterators
of :class:`can.Message` that never stop on a bad line: an unparseable line is counted in
:class:`ReadStats` (and reported as rejected ``malformed`` by the decoder) and reading goes
on; a binary file cut short ends the iteration with ``ReadStats.truncated`` set. The
candump parser exists for speed: python-can's reader builds each payload byte by byte and
stops at the first bad line; ours uses ``bytearray.fromhex`` and reads ~2x faster.

For the decoder's batch path, :func:`read_log_arrays` gives the same frames as
:class:`FrameArrays` (parallel NumPy arrays): candump logs are parsed with array
operations on the file's bytes (:func:`read_candump_arrays`, ~10x the message reader, bad
lines still counted with the same reasons and line numbers), the other formats are
converted from python-can messages.

Timestamps written equal the frames' ``timestamp`` to the format's resolution (1 µs for
``.log``/``.asc``/``.trc``; BLF stores nanoseconds); the ASC writer anchors the
``Begin Triggerblock`` date on the whole millisecond so that absolute times read back
exactly (python-can's would drop the sub-millisecond part of the first timestamp).
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
from bisect import bisect_left
from dataclasses import dataclass, field
from datetime import datetime
from decimal import Decimal
from pathlib import Path
from typing import Callable, Iterable, Iterator, Optional, Sequence, TextIO, cast

import can
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from suspid.can.damage import blf_damage, mdf_damage
from suspid.can.formats import FORMATS
from suspid.errors import InputError, UsageError

_CAN_ERR_FLAG = 0x20000000
#: candump lines handed to python-can's reader at once
_ODD_BLOCK = 4096
#: characters of a hex payload
_HEX_DIGITS = "0123456789abcdefABCDEF"
_CAN_EFF_FLAG = 0x80000000


#: text formats also read gzip-compressed (``F.asc.gz``), as python-can's ``LogReader`` does
GZIP_READ = (".asc", ".trc")


def _suffix(path: str | Path, compressed: bool = True) -> str:
    """The format suffix of ``path``, lower case: ``.asc`` for ``F.asc`` and, with
    ``compressed``, for ``F.asc.gz`` (:data:`GZIP_READ`)."""
    p = Path(path)
    suf = p.suffix.lower()
    inner = Path(p.stem).suffix.lower()
    return inner if compressed and suf == ".gz" and inner in GZIP_READ else suf


def log_format(path: str | Path, option: str = "log", compressed: bool = True) -> str:
    """Normalised suffix of a CAN log path (``.asc`` for a gzip-compressed ``F.asc.gz``
    too, unless ``compressed`` is false: a writer writes plain files).

    Raises
    ------
    UsageError
        For a suffix that is not a known CAN log format, naming the known ones.
    """
    suf = _suffix(path, compressed)
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
    """``True`` if the path's suffix names a CAN log format of :data:`LOG_FORMATS`
    (case-insensitive)."""
    return _suffix(path) in LOG_FORMATS


#: what python-can's reader of a format gives as ``Message.channel`` for the file's channel 1:
#: ASC and BLF count from 1 in the file and python-can gives ``0``; TRC's bus column and
#: MDF4's ``BusChannel`` are given as written (``1``); candump names the interface
#: (``can0``), a string
_CHANNEL_BASE = {".asc": 1, ".blf": 1, ".trc": 0, ".mf4": 0}
#: an option value naming a numbered channel: ``1``, ``CAN1`` (CANedge), ``ch1``, ``channel 1``
_CHANNEL_NUMBER = re.compile(r"(?:can|ch|channel)?\s*(\d+)", re.IGNORECASE)
#: the label of a frame without a channel (an MDF4 file without ``BusChannel``)
NO_CHANNEL = "none"


def channel_label(suffix: str, channel: object) -> str:
    """A frame's bus channel as the log file names it (what a user reads in the file).

    Parameters
    ----------
    suffix : str
        The log's format (lower case, ``".asc"``).
    channel : int, str or None
        :attr:`can.Message.channel` as python-can's reader of that format gives it.

    Returns
    -------
    str
        ``"1"``, ``"2"``, ... for the numbered formats (ASC/BLF channel 1, TRC bus 1,
        MDF4 ``BusChannel`` 1 = CANedge CAN1), the interface name for candump
        (``"can0"``), :data:`NO_CHANNEL` when the frame carries none.
    """
    if channel is None:
        return NO_CHANNEL
    if isinstance(channel, (int, np.integer)) and not isinstance(channel, bool):
        return str(int(channel) + _CHANNEL_BASE.get(suffix, 0))
    return str(channel)


def channel_wanted(suffix: str, text: str) -> str:
    """The channel label (:func:`channel_label`) that an option value names in a log.

    For the numbered formats ``1``, ``CAN1``, ``ch1`` and ``channel 1`` all name channel 1;
    for candump the value is the interface name as written (``can1``).
    """
    text = text.strip()
    if suffix == ".log":
        return text
    m = _CHANNEL_NUMBER.fullmatch(text)
    return str(int(m.group(1))) if m else text


def _channel_order(label: str) -> tuple[int, int, str]:
    """Sort key of channel labels: numbers in numeric order, then names."""
    return (0, int(label), "") if label.isdigit() else (1, 0, label)


def describe_channels(counts: dict[str, int]) -> str:
    """``"1 (1200 frames), 2 (1200 frames)"``, or ``"no frames"`` for a log without any."""
    return ", ".join(f"{ch} ({n} frames)" for ch, n in counts.items()) or "no frames"


#: frame keys (CAN ID | extended flag << 31) below ``_KEY_SPAN`` are counted per channel as
#: one int64 ``code << _KEY_BITS | key``
_KEY_BITS = 40
_KEY_SPAN = 1 << _KEY_BITS


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
    channels : dict
        Per bus channel of the log, as the file names it (:func:`channel_label`: ``"1"``,
        ``"can0"``): frame key (CAN ID, bit 31 set for an extended one) -> frames read.
        Filled by :func:`read_log` and :func:`read_log_arrays`.
    other_channel : int
        Frames of other channels than the one asked for, skipped (not yielded).
    damage : str
        Where a binary file is damaged (:mod:`suspid.can.damage`), one line naming the file
        and the byte; ``""`` for a whole file. Counted once in ``malformed``.
    """

    frames: int = 0
    malformed: int = 0
    truncated: bool = False
    examples: list[str] = field(default_factory=list)
    channels: dict[str, dict[int, int]] = field(default_factory=dict)
    other_channel: int = 0
    damage: str = ""

    def count_channels(self, codes: np.ndarray, names: Sequence[str], keys: np.ndarray) -> None:
        """Count frames per channel and key (``codes`` index ``names``, one per frame)."""
        if not codes.size:
            return
        pairs: Iterable[tuple[int, int]]
        if len(names) == 1 or not np.any(codes != codes[0]):
            # one channel (the usual log): the keys alone, in their own width
            uniq, counts = np.unique(keys, return_counts=True)
            code0 = int(codes[0])
            pairs = ((code0, int(k)) for k in uniq.tolist())
        elif int(keys.min()) >= 0 and int(keys.max()) < _KEY_SPAN:   # one sort of int64
            uniq, counts = np.unique((codes.astype(np.int64) << _KEY_BITS) | keys,
                                     return_counts=True)
            pairs = ((u >> _KEY_BITS, u & (_KEY_SPAN - 1)) for u in uniq.tolist())
        else:   # an identifier beyond 29 bits from an odd line: pairs sorted as rows
            rows, counts = np.unique(np.stack([codes.astype(np.int64),
                                               np.asarray(keys, dtype=np.int64)], axis=1), axis=0,
                                     return_counts=True)
            pairs = ((int(c), int(k)) for c, k in rows.tolist())
        for (code, k), c in zip(pairs, counts.tolist()):
            per = self.channels.setdefault(names[code], {})
            per[k] = per.get(k, 0) + c

    def channel_frames(self, keys: Optional[Iterable[int]] = None) -> dict[str, int]:
        """Frames per channel (``keys`` given: of those frame keys only), in channel order."""
        want = None if keys is None else set(keys)
        out = {ch: sum(n for k, n in per.items() if want is None or k in want)
               for ch, per in self.channels.items()}
        return dict(sorted(out.items(), key=lambda kv: _channel_order(kv[0])))

    def damaged(self, path: Path, what: str) -> None:
        """Record the damage of a binary file (the first one named): truncated, one record
        counted ``malformed``."""
        self.truncated = True
        if not self.damage:
            self.malformed += 1
            self.damage = f"{path}: damaged {log_format(path, 'CAN log')[1:].upper()} file: {what}"

    def bad(self, where: str, reason: str) -> None:
        """Count one skipped line/record and keep the first five reasons."""
        self.malformed += 1
        if len(self.examples) < 5:
            self.examples.append(f"{where}: {' '.join(reason.split())[:120]}")


def _line_fault(parts: list[str]) -> str | None:
    """Why the fields of a candump -L line are no frame (``None``: they may be one).

    The checks python-can's reader does not make, or makes with an unhelpful error: the
    ``(seconds)`` first, ``ID#DATA`` third, at most 8 bytes in a classic frame.
    """
    ts_s = parts[0]
    if ts_s[0] != "(" or ts_s[-1] != ")":
        return f"expected '(seconds)' first, got {ts_s[:24]!r}"
    if len(parts) < 3:
        return "expected '(seconds) interface ID#DATA'"
    id_s, sep, data_s = parts[2].partition("#")
    if not sep:
        return f"expected ID#DATA, got {parts[2][:24]!r}"
    if data_s[:1] in ("R", "r"):
        return None
    payload = data_s[2:] if data_s[:1] == "#" else data_s
    if len(payload) % 2 or payload.strip(_HEX_DIGITS):
        return f"payload {data_s[:24]!r} is not hex"
    if data_s[:1] != "#" and len(payload) > 16:
        return f"{len(payload) // 2} data bytes in a classic CAN frame"
    return None


def _canutils(lines: list[str]) -> list[can.Message]:
    """python-can's :class:`can.CanutilsLogReader` over ``lines`` (one frame each)."""
    return list(can.CanutilsLogReader(io.StringIO("\n".join(lines))))


def _candump_odd(path: Path, numbered: Iterable[tuple[int, int, str]],
                 stats: ReadStats) -> Iterator[tuple[int, can.Message]]:
    """The candump -L lines the array parser (:func:`_candump_chunk`) leaves: CAN FD
    ``ID##<flags><data>``, remote ``ID#R[len]``, odd spacing, bad lines.

    ``numbered`` gives ``(tag, lineno, text)``; yields ``(tag, message)`` in line order.
    The lines are read by python-can's :class:`can.CanutilsLogReader` (a block of lines at
    once; a block it fails on line by line); error frames (the error flag in an extended
    ID) are made as the array parser makes them, the interface name is kept as text. A
    line that is no frame is counted in ``stats`` as ``path:lineno`` with the reason.
    """
    frames = 0
    block: list[tuple[int, int, list[str], str | None]] = []
    it = iter(numbered)
    try:
        while True:
            block.clear()
            for tag, lineno, line in it:
                parts = line.split()
                if parts:
                    block.append((tag, lineno, parts[:3] + [f for f in parts[3:4]
                                                            if f.lower() in ("r", "t")],
                                  _line_fault(parts)))
                    if len(block) >= _ODD_BLOCK:
                        break
            if not block:
                return
            good = [" ".join(p) for _, _, p, why in block if why is None]
            try:
                msgs = iter(_canutils(good))
                failed: dict[int, str] = {}
            except (ValueError, IndexError):   # the block line by line
                got: list[can.Message] = []
                failed = {}
                for k, (_, _, parts, why) in enumerate(block):
                    if why is None:
                        try:
                            got.extend(_canutils([" ".join(parts)]))
                        except (ValueError, IndexError) as exc:
                            failed[k] = str(exc) or "unparseable line"
                msgs = iter(got)
            for k, (tag, lineno, parts, why) in enumerate(block):
                why = why or failed.get(k)
                if why is not None:
                    stats.bad(f"{path}:{lineno}", why)
                    continue
                msg = next(msgs)
                frames += 1
                id_s = parts[2].partition("#")[0]
                if int(id_s, 16) & _CAN_ERR_FLAG and len(id_s) > 3:
                    msg = can.Message(timestamp=msg.timestamp, is_error_frame=True, check=False)
                msg.channel = parts[1]
                yield tag, msg
    finally:
        stats.frames += frames


def _read_candump(path: Path, stats: ReadStats) -> Iterator[can.Message]:
    """candump -L lines as :class:`can.Message`: the array reader's frames
    (:func:`read_candump_arrays`), each with its interface as ``channel``.

    Read 64 KiB at a time (~1,500 frames): a stream of messages keeps the parse's
    temporaries (~7x the chunk) small whatever the log's length.
    """
    for fa, codes, names in _candump_labelled(path, stats, 1 << 16):
        yield from fa.iter_messages(names, codes)


# ---- frames as arrays ----------------------------------------------------------------------
@dataclass
class FrameArrays:
    """A batch of CAN frames as parallel NumPy arrays (the decoder's vectorized input).

    Attributes
    ----------
    timestamp : ndarray of float64, shape (N,)
        Frame times (s), as :attr:`can.Message.timestamp`.
    arbitration_id : ndarray of int64, shape (N,)
        CAN identifiers (without the extended flag).
    is_extended : ndarray of bool, shape (N,)
        29-bit identifier.
    frame_type : ndarray of bool, shape (N,)
        Error or remote frame (no data; the decoder rejects it as ``frame_type``).
    length : ndarray of int64, shape (N,)
        Payload length (bytes), ``len(msg.data)``.
    data : ndarray of uint8, shape (N, 8)
        Payloads, zero beyond ``length``; frames longer than 8 bytes (CAN FD) hold their
        first 8 bytes here and the whole payload in ``long_data``.
    long_data : dict
        ``row index -> payload`` of the frames longer than 8 bytes.
    """

    timestamp: np.ndarray
    arbitration_id: np.ndarray
    is_extended: np.ndarray
    frame_type: np.ndarray
    length: np.ndarray
    data: np.ndarray
    long_data: dict[int, bytes] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.timestamp.shape[0])

    @classmethod
    def empty(cls) -> "FrameArrays":
        """A batch of no frames."""
        return cls(np.empty(0), np.empty(0, np.int64), np.empty(0, bool), np.empty(0, bool),
                   np.empty(0, np.int64), np.empty((0, 8), np.uint8))

    @classmethod
    def from_messages(cls, messages: Sequence[can.Message]) -> "FrameArrays":
        """The fields of python-can messages as arrays (what the decoder reads of a frame)."""
        n = len(messages)
        ts = np.array([m.timestamp for m in messages], dtype=np.float64).reshape(n)
        ids = np.array([m.arbitration_id for m in messages], dtype=np.int64).reshape(n)
        ext = np.frombuffer(bytes([bool(m.is_extended_id) for m in messages]), dtype=bool)
        odd = [bool(m.is_error_frame or m.is_remote_frame) for m in messages]
        ft = np.frombuffer(bytes(odd), dtype=bool) if True in odd else np.zeros(n, dtype=bool)
        payloads: list[bytes | bytearray] = [m.data for m in messages]
        lens = np.array(list(map(len, payloads)), dtype=np.int64).reshape(n)
        try:
            joined = b"".join(payloads)
        except TypeError:  # a payload that is not bytes-like (assigned after construction)
            payloads = [bytes(p) for p in payloads]
            joined = b"".join(payloads)
        flat = np.frombuffer(joined, dtype=np.uint8)
        long_data: dict[int, bytes] = {}
        if n and flat.size == 8 * n and bool((lens == 8).all()):
            data = flat.reshape(n, 8)
        elif n and int(lens.max()) <= 8:   # short payloads padded to 8 bytes in one join
            data = np.frombuffer(b"".join([p if len(p) == 8 else bytes(p).ljust(8, b"\0")
                                           for p in payloads]), dtype=np.uint8).reshape(n, 8)
        else:
            data = np.zeros((n, 8), dtype=np.uint8)
            if n:
                offs = np.zeros(n, dtype=np.int64)
                np.cumsum(lens[:-1], out=offs[1:])
                cols = np.arange(8)
                mask = cols[None, :] < np.minimum(lens, 8)[:, None]
                data[mask] = flat[(offs[:, None] + cols[None, :])[mask]]
                for i in np.flatnonzero(lens > 8).tolist():
                    long_data[i] = bytes(payloads[i])
        return cls(ts, ids, ext, ft, lens, data, long_data)

    def select(self, rows: np.ndarray) -> "FrameArrays":
        """The frames where the boolean mask ``rows`` is true, in order."""
        out = FrameArrays(self.timestamp[rows], self.arbitration_id[rows], self.is_extended[rows],
                          self.frame_type[rows], self.length[rows], self.data[rows])
        if self.long_data:
            new = np.cumsum(rows) - 1
            out.long_data = {int(new[i]): v for i, v in self.long_data.items() if rows[i]}
        return out

    def payload(self, i: int) -> bytes:
        """Payload of frame ``i``."""
        got = self.long_data.get(i)
        if got is not None:
            return got
        return self.data[i, :int(self.length[i])].tobytes()

    def messages(self, channels: Sequence[str] | None = None,
                 codes: np.ndarray | None = None) -> list[can.Message]:
        """The frames as python-can messages (see :meth:`iter_messages`)."""
        return list(self.iter_messages(channels, codes))

    def iter_messages(self, channels: Sequence[str] | None = None,
                      codes: np.ndarray | None = None) -> Iterator[can.Message]:
        """The frames as python-can messages, one at a time: what the decoder reads of a
        frame (time, ID, payload; error and remote frames as error frames, payloads over 8
        bytes as CAN FD), with ``channels[codes[i]]`` as frame ``i``'s channel when given."""
        ts = self.timestamp.tolist()
        ids = self.arbitration_id.tolist()
        ext = self.is_extended.tolist()
        ft = self.frame_type.tolist()
        lens = self.length.tolist()
        raw = np.ascontiguousarray(self.data).tobytes()
        chan: list[str | None] = [None] * len(ts) if channels is None or codes is None else \
            [channels[c] for c in np.broadcast_to(codes, (len(ts),)).tolist()]
        long_data = self.long_data
        Message = can.Message
        for i in range(len(ts)):
            got = long_data.get(i) if long_data else None
            data = bytearray(raw[8 * i:8 * i + min(lens[i], 8)] if got is None else got)
            yield Message(timestamp=ts[i], arbitration_id=ids[i], is_extended_id=ext[i],
                          is_error_frame=ft[i], data=data, channel=chan[i],
                          is_fd=lens[i] > 8, check=False)


#: hex digit value per byte, 255 = not a hex digit
_HEXVAL = np.full(256, 255, dtype=np.uint8)
for _k, _c in enumerate(b"0123456789abcdef"):
    _HEXVAL[_c] = _k
for _k, _c in enumerate(b"ABCDEF"):
    _HEXVAL[_c] = 10 + _k
#: decimal digit value per byte, 255 = not a digit
_DIGVAL = np.full(256, 255, dtype=np.uint8)
_DIGVAL[48:58] = np.arange(10)
#: byte value of two hex digits read as a little-endian uint16; 0x100 = not two hex digits
_HEXPAIR = np.full(1 << 16, 0x100, dtype=np.uint16)
_hv = np.flatnonzero(_HEXVAL != 255)
_HEXPAIR[(_hv[:, None] | (_hv[None, :] << 8)).ravel()] = \
    ((_HEXVAL[_hv][:, None] << 4) | _HEXVAL[_hv][None, :]).ravel()
#: longest line (bytes) the array parser takes; longer ones go through the message parser
_MAX_FAST_LINE = 160
#: integers below this are exact in float64
_EXACT_INT = float(2 ** 53)
#: line layouts tried per line length before the rest of that length goes line by line
_MAX_LAYOUTS = 8


def _line_layout(line: bytes) -> tuple[int, int, int, int, int, int] | None:
    """Byte positions ``(close, dot, sp1, sp2, hash, sp3)`` of a regular candump line.

    Regular: ``(DIGITS.DIGITS) IFACE HEXID#HEXDATA[ ...]`` with single spaces, any number
    of timestamp digits (epoch times such as ``1631416514.717133`` have 16; the value is
    converted exactly whatever the count, see :func:`_parse_layout`), 1-8 ID digits and an
    even number (<= 16) of data digits; ``None`` otherwise. Only positions are read here:
    the characters are checked by the caller for every line sharing the layout.
    """
    if line[:1] != b"(":
        return None
    close = line.find(b")")
    sp1 = close + 1
    if close < 3 or line[sp1:sp1 + 1] != b" ":
        return None
    dot = line.find(b".", 1, close)
    if dot < 2 or dot > close - 2:
        return None
    sp2 = line.find(b" ", sp1 + 1)
    if sp2 <= sp1 + 1:
        return None
    sp3 = line.find(b" ", sp2 + 1)
    if sp3 < 0:
        sp3 = len(line)
    hs = line.find(b"#", sp2 + 1, sp3)
    if hs < 0 or not 1 <= hs - sp2 - 1 <= 8 or (sp3 - hs - 1) % 2 or sp3 - hs - 1 > 16:
        return None
    return close, dot, sp1, sp2, hs, sp3


def _digits_value(chars: np.ndarray, lut: np.ndarray, base: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """``(value, ok)`` of rows of digit characters (decimal or hex by ``lut``/``base``).

    Exact while the value is below 2**53 (up to 15 decimal or 13 hex digits): every partial
    value is then an integer below 2**53. A longer row may be rounded, but never below
    2**53 once the exact value reaches it (each step rounds a non-decreasing result to
    nearest and 2**53 is a float), so ``value < 2**53`` proves the value exact.
    """
    d = lut[chars]
    acc = d[:, 0].astype(np.float64)
    bad = d[:, 0].copy()
    for j in range(1, chars.shape[1]):
        col = d[:, j]
        acc *= base
        acc += col
        bad |= col
    return acc, bad < 16   # digit values 0..15; 255 marks any other character


def _parse_layout(rows: np.ndarray, layout: tuple[int, int, int, int, int, int]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Parse lines of one layout (``rows`` (m, L) uint8, one line per row).

    Returns ``(good, timestamp, arbitration_id, data)``; ``good`` is False for a row whose
    characters do not fit the layout (it goes through the message parser instead).
    """
    close, dot, sp1, sp2, hs, sp3 = layout
    m, length = rows.shape
    good = (rows[:, 0] == 40) & (rows[:, close] == 41) & (rows[:, sp1] == 32)
    good &= (rows[:, dot] == 46) & (rows[:, sp2] == 32) & (rows[:, hs] == 35)
    if sp3 < length:
        good &= rows[:, sp3] == 32
    for j in range(sp1 + 1, sp2):                                   # interface: no blank
        good &= rows[:, j] > 32
    n_int, ok_int = _digits_value(rows[:, 1:dot], _DIGVAL, 10.0)
    n_frac, ok_frac = _digits_value(rows[:, dot + 1:close], _DIGVAL, 10.0)
    nf = close - dot - 1
    good &= ok_int & ok_frac
    # The timestamp INT.FRAC is the integer N = INT * 10**nf + FRAC over 10**nf. While
    # N < 2**53 (every candump/python-can time "%.6f" before the year 2255: 1631416514.717133
    # is N = 1.6e15) N is exact, and so is 10**nf for nf <= 22: one IEEE division then
    # gives the correctly rounded quotient, which is what float(str) returns (Clinger's
    # fast path). INT + FRAC / 10**nf would round twice: 1 ulp off for 3.794462 and for
    # ~5 % of random one-digit-second times.
    # A computed N below 2**53 proves the exact one is (see _digits_value); the other rows
    # (17+ significant digits, e.g. nanosecond epoch times) are converted by float() itself.
    if nf <= 22:
        p10 = float(10 ** nf)
        num = n_int * p10 + n_frac
        ts = num / p10
    else:   # 10**nf is not a float: every row by float()
        num = np.full(m, _EXACT_INT)
        ts = np.zeros(m)
    id_value, ok_id = _digits_value(rows[:, sp2 + 1:hs], _HEXVAL, 16.0)
    good &= ok_id
    ids = id_value.astype(np.int64)
    data = np.zeros((m, 8), dtype=np.uint8)
    nb = (sp3 - hs - 1) // 2
    if nb:
        pairs = _HEXPAIR[np.ascontiguousarray(rows[:, hs + 1:sp3]).view(np.uint16)]
        bad = pairs[:, 0] >> 8
        for j in range(1, nb):
            bad |= pairs[:, j] >> 8
        good &= bad == 0
        data[:, :nb] = pairs
    inexact = np.flatnonzero(good & ~(num < _EXACT_INT))
    if inexact.size:
        text = np.ascontiguousarray(rows[inexact, 1:close]).view(f"S{close - 1}").ravel()
        ts[inexact] = [float(t) for t in text.tolist()]
    return good, ts, ids, data


#: interfaces told apart by comparisons in one layout of a chunk, before a sort does it
_FEW_NAMES = 4


def _name_codes(iface: np.ndarray, code_of: Callable[[str], int]) -> np.ndarray | int:
    """The code (``code_of(name)``) of each fixed-width interface name of ``iface`` (an
    ``S<n>`` array): one code when all are equal, else a comparison per name while there are
    few (a log of two or three buses), a sort beyond."""
    first = iface[0]
    same = iface == first
    if bool(same.all()):
        return code_of(bytes(first).decode("ascii", errors="replace"))
    out = np.empty(iface.size, dtype=np.int32)
    out[same] = code_of(bytes(first).decode("ascii", errors="replace"))
    left = np.flatnonzero(~same)
    for _ in range(_FEW_NAMES):
        name = iface[left[0]]
        same = iface[left] == name
        out[left[same]] = code_of(bytes(name).decode("ascii", errors="replace"))
        left = left[~same]
        if not left.size:
            return out
    uniq, inv = np.unique(iface[left], return_inverse=True)
    out[left] = np.array([code_of(bytes(u).decode("ascii", errors="replace"))
                          for u in uniq.tolist()], dtype=np.int32)[inv.reshape(-1)]
    return out


def _candump_chunk(buf: bytes, path: Path, line0: int, stats: ReadStats
                   ) -> tuple[FrameArrays, int, np.ndarray, list[str]]:
    """Parse whole candump -L lines (``buf`` ends at a line end or at the file end).

    Lines are grouped by length; a group's first line gives the byte positions of the
    fields (:func:`_line_layout`) and every line of that layout is parsed at once with
    column operations (:func:`_parse_layout`). Lines that fit no layout -- malformed, FD,
    remote, odd spacing, control characters -- go through :func:`_candump_odd` (python-can's
    reader), in file order, with the bad lines counted by file line number. Returns the frames in file order, the number of lines (for numbering the
    next chunk; a lone ``\\r`` is a line break of its own, as for a text reader), and each
    frame's interface as a code (int64 per frame) into a list of interface names.
    """
    b = np.frombuffer(buf, dtype=np.uint8)
    nl = np.flatnonzero(b == 10)
    ends = nl if (b.size == 0 or b[-1] == 10) else np.append(nl, b.size)
    nlines = int(ends.size)
    starts = np.zeros(nlines, dtype=np.int64)
    starts[1:] = ends[:-1] + 1
    e = ends.astype(np.int64)
    nonempty = e > starts
    slow = np.zeros(nlines, dtype=bool)
    extra_at: list[tuple[int, int]] = []   # (line, lone "\\r" in it)
    if buf.find(b"\r") >= 0:
        # "\\r\\n" is one line break (universal newlines): the "\\r" is not part of the line
        cr = nonempty & (b[np.maximum(e - 1, 0)] == 13)
        e[cr] -= 1
        crs = np.flatnonzero(b == 13)
        li = np.searchsorted(starts, crs, side="right") - 1
        inner = crs < e[li]
        if inner.any():
            u, cnt = np.unique(li[inner], return_counts=True)
            slow[u] = True
            extra_at = list(zip(u.tolist(), cnt.tolist()))
    length = e - starts
    lt = np.zeros(nlines)
    lid = np.zeros(nlines, dtype=np.int64)
    lidlen = np.zeros(nlines, dtype=np.int64)
    lnb = np.zeros(nlines, dtype=np.int64)
    ldata = np.zeros((nlines, 8), dtype=np.uint8)
    ldata64 = ldata.view(np.uint64).reshape(nlines)    # one 8-byte store per row
    fast = np.zeros(nlines, dtype=bool)
    lcode = np.zeros(nlines, dtype=np.int32)
    names: list[str] = []
    name_code: dict[str, int] = {}

    def code_of(name: str) -> int:
        c = name_code.get(name)
        if c is None:
            c = name_code[name] = len(names)
            names.append(name)
        return c

    cand = (length >= 10) & (length <= _MAX_FAST_LINE) & ~slow
    cidx = np.flatnonzero(cand)
    if cidx.size:
        clen = length[cidx]
        padded = np.concatenate((b, np.zeros(_MAX_FAST_LINE, dtype=np.uint8)))
        for L in np.flatnonzero(np.bincount(clen)).tolist():
            sel = clen == L
            idx = cidx if sel.all() else cidx[sel]
            rows = sliding_window_view(padded, L)[starts[idx]]
            left = np.arange(idx.size)
            for _ in range(_MAX_LAYOUTS):
                if not left.size:
                    break
                layout = _line_layout(rows[left[0]].tobytes())
                if layout is None:
                    left = left[1:]
                    continue
                whole = left.size == idx.size
                good, ts, ids, data = _parse_layout(rows if whole else rows[left], layout)
                all_good = bool(good.all())
                at = idx if whole and all_good else idx[left[good]]
                if not all_good:
                    ts, ids, data = ts[good], ids[good], data[good]
                fast[at] = True
                lt[at] = ts
                lid[at] = ids
                lidlen[at] = layout[4] - layout[3] - 1
                lnb[at] = (layout[5] - layout[4] - 1) // 2
                ldata64[at] = data.view(np.uint64).reshape(-1)
                sp1, sp2 = layout[2], layout[3]
                part = rows if whole else rows[left]
                iface = np.ascontiguousarray(part[:, sp1 + 1:sp2]).view(f"S{sp2 - sp1 - 1}")
                iface = iface.reshape(-1) if all_good else iface.reshape(-1)[good]
                if iface.size:
                    lcode[at] = _name_codes(iface, code_of)
                left = left[~good]
    # every other non-empty line: the message parser, in file order, in one pass
    slow_msgs: list[can.Message] = []
    slow_line: list[int] = []     # per message: its line (index in this chunk)
    slow_lines = np.flatnonzero(nonempty & ~fast).tolist()
    per_line = fast.astype(np.int64) if slow_lines else fast
    if slow_lines:
        extra_lines = [x for x, _ in extra_at]
        extra_cum = np.cumsum([0] + [c for _, c in extra_at]).tolist()
        line_start = starts.tolist()
        line_end = e.tolist()
        def numbered() -> Iterator[tuple[int, int, str]]:
            for i in slow_lines:
                lineno = line0 + i + 1
                if extra_lines:
                    lineno += extra_cum[bisect_left(extra_lines, i)]
                text = buf[line_start[i]:line_end[i]].decode("ascii", errors="replace")
                if "\r" in text:
                    for k, sub in enumerate(text.split("\r")):
                        yield i, lineno + k, sub
                else:
                    yield i, lineno, text

        for i, msg in _candump_odd(path, numbered(), stats):
            slow_msgs.append(msg)
            slow_line.append(i)
    n_fast = int(np.count_nonzero(fast))
    stats.frames += n_fast
    total_lines = nlines + sum(c for _, c in extra_at)
    ext = lidlen > 3
    ft = ((lid & _CAN_ERR_FLAG) != 0) & ext
    if ft.any():   # error frames: no identifier, no data (as the message reader makes them)
        lid[ft] = 0
        lnb[ft] = 0
        ldata[ft] = 0
    if not slow_msgs:   # every frame from a regular line: in file order already
        if n_fast == nlines:
            return FrameArrays(lt, lid, ext, ft, lnb, ldata), total_lines, lcode, names
        return (FrameArrays(lt[fast], lid[fast], ext[fast], ft[fast], lnb[fast], ldata[fast]),
                total_lines, lcode[fast], names)
    where = np.array(slow_line, dtype=np.int64)
    np.add.at(per_line, where, 1)
    n = int(per_line.sum())
    offs = np.cumsum(per_line) - per_line
    out = FrameArrays(np.zeros(n), np.zeros(n, np.int64), np.zeros(n, bool), np.zeros(n, bool),
                      np.zeros(n, np.int64), np.zeros((n, 8), np.uint8))
    codes = np.zeros(n, np.int32)
    at = offs[fast]
    codes[at] = lcode[fast]
    out.timestamp[at] = lt[fast]
    out.arbitration_id[at] = lid[fast]
    out.is_extended[at] = ext[fast]
    out.frame_type[at] = ft[fast]
    out.length[at] = lnb[fast]
    out.data[at] = ldata[fast]
    # the line-by-line frames, converted at once (a conversion per line made a log of
    # irregular lines ~10x slower to read)
    extra = FrameArrays.from_messages(slow_msgs)
    first = np.flatnonzero(np.r_[True, where[1:] != where[:-1]])   # a line's first frame
    nth = np.arange(where.size) - np.repeat(first, np.diff(np.r_[first, where.size]))
    at = offs[where] + nth
    codes[at] = [code_of(str(m.channel)) for m in slow_msgs]
    out.timestamp[at] = extra.timestamp
    out.arbitration_id[at] = extra.arbitration_id
    out.is_extended[at] = extra.is_extended
    out.frame_type[at] = extra.frame_type
    out.length[at] = extra.length
    out.data[at] = extra.data
    for j, payload in extra.long_data.items():
        out.long_data[int(at[j])] = payload
    return out, total_lines, codes, names


def read_candump_arrays(path: str | Path, stats: Optional[ReadStats] = None, *,
                        chunk_bytes: int = 1 << 19) -> Iterator[FrameArrays]:
    """The frames of a candump -L log as :class:`FrameArrays`, about ``chunk_bytes`` at a time.

    Same frames, malformed-line counts, reasons and line numbers as the message reader
    (:func:`read_log`), ~10x faster: the regular lines are parsed with array operations on
    the file's bytes, the rest line by line.

    Parameters
    ----------
    path : str or Path
        A candump -L log.
    stats : ReadStats, optional
        Filled with frames read and lines skipped, and the frames per interface.
    chunk_bytes : int
        Bytes read per step (a chunk ends at a line end; 512 KiB is ~12 k frames). The
        parse's temporaries are about 7x the chunk, so this bounds the reader's memory
        whatever the log's length; larger chunks are no faster (measured: 8 MiB and 512 KiB
        load a 79 k-frame log in the same 100 ms, with a peak of 21.7 MB against 7.9 MB).

    Raises
    ------
    InputError
        The file cannot be opened.
    """
    p = Path(path)
    st = stats if stats is not None else ReadStats()
    return _select_arrays(p, ".log", _candump_labelled(p, st, chunk_bytes), st, None)


#: a batch of frames with each frame's channel: ``(frames, codes, names)``, ``names[codes[i]]``
#: the channel label (:func:`channel_label`) of frame ``i``
LabelledFrames = tuple[FrameArrays, np.ndarray, list[str]]


def _candump_labelled(p: Path, stats: Optional[ReadStats],
                      chunk_bytes: int = 1 << 19) -> Iterator[LabelledFrames]:
    """:func:`read_candump_arrays` with each frame's interface (see :data:`LabelledFrames`)."""
    st = stats if stats is not None else ReadStats()
    try:
        fh = p.open("rb")
    except OSError as exc:
        raise InputError(f"{p}: cannot open CAN log: {exc.strerror}") from None
    with fh:
        rest = b""
        line0 = 0
        while True:
            blk = fh.read(max(1, chunk_bytes))
            if blk:
                buf = rest + blk
                cut = buf.rfind(b"\n") + 1
                if cut == 0:
                    rest = buf
                    continue
                buf, rest = buf[:cut], buf[cut:]
            else:
                buf, rest = rest, b""
                if not buf:
                    return
            fa, nlines, codes, names = _candump_chunk(buf, p, line0, st)
            line0 += nlines
            if len(fa):
                yield fa, codes, names
            if not blk:
                return


def read_log_arrays(path: str | Path, stats: Optional[ReadStats] = None, *,
                    chunk: int = 65536, channel: Optional[str] = None) -> Iterator[FrameArrays]:
    """The frames of a CAN log (format by suffix) as :class:`FrameArrays` batches.

    candump -L (``.log``) goes through :func:`read_candump_arrays`; the python-can formats
    are read as messages (:func:`read_log`) and converted ``chunk`` frames at a time.
    Same checks, errors, ``channel`` selection and :class:`ReadStats` as :func:`read_log`.
    """
    p, suf, st = _open_log(path, stats)
    batches = LOG_FORMATS[suf].read_arrays
    if batches is not None:
        return _select_arrays(p, suf, batches(p, st), st, channel)
    return _message_batches(read_log(p, st, channel=channel), chunk)


def _missing_channel(path: Path, channel: str, stats: ReadStats) -> UsageError:
    """The one-line error of a channel option naming no channel of the log."""
    return UsageError(f"{path}: can.channel {channel}: no such channel in the log; "
                      f"channels present: {describe_channels(stats.channel_frames())}")


def _select_arrays(path: Path, suf: str, chunks: Iterator[LabelledFrames], st: ReadStats,
                   channel: Optional[str]) -> Iterator[FrameArrays]:
    """The frames of ``channel`` (all when ``None``) of labelled batches, every frame
    counted per channel in ``st``; a channel absent from the log raises at the end."""
    want = None if channel is None else channel_wanted(suf, channel)
    for fa, codes, names in chunks:
        keys = np.array(fa.arbitration_id, dtype=np.int64)    # CAN ID | extended << 31
        keys[fa.is_extended] |= 1 << 31
        st.count_channels(codes, names, keys)
        if want is not None:
            keep = np.array([n == want for n in names], dtype=bool)[codes]
            n_keep = int(np.count_nonzero(keep))
            st.other_channel += len(fa) - n_keep
            if n_keep < len(fa):
                fa = fa.select(keep)
        if len(fa):
            yield fa
    if want is not None and want not in st.channels:
        raise _missing_channel(path, str(channel), st)


def _select_messages(path: Path, suf: str, messages: Iterator[can.Message], st: ReadStats,
                     channel: Optional[str]) -> Iterator[can.Message]:
    """:func:`_select_arrays` for messages."""
    want = None if channel is None else channel_wanted(suf, channel)
    counts: dict[tuple[str, int], int] = {}
    last: object = object()
    label = ""
    try:
        for msg in messages:
            ch = msg.channel
            if ch is not last:
                last, label = ch, channel_label(suf, ch)
            key = (label, msg.arbitration_id | (bool(msg.is_extended_id) << 31))
            counts[key] = counts.get(key, 0) + 1
            if want is None or label == want:
                yield msg
            else:
                st.other_channel += 1
    finally:
        for (lab, k), n in counts.items():
            per = st.channels.setdefault(lab, {})
            per[k] = per.get(k, 0) + n
    if want is not None and want not in st.channels:
        raise _missing_channel(path, str(channel), st)


def _message_batches(messages: Iterable[can.Message], chunk: int) -> Iterator[FrameArrays]:
    batch: list[can.Message] = []
    for msg in messages:
        batch.append(msg)
        if len(batch) >= chunk:
            yield FrameArrays.from_messages(batch)
            batch = []
    if batch:
        yield FrameArrays.from_messages(batch)


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


def _read_asc(path: Path, stats: ReadStats) -> Iterator[can.Message]:
    counter = _open_text(path, _AscLines)
    try:
        reader = can.ASCReader(cast(TextIO, counter), relative_timestamp=False)   # duck-typed
    except BaseException:
        counter.fh.close()
        raise
    return _read_text_resumable(path, reader, counter, stats)


def _read_trc(path: Path, stats: ReadStats) -> Iterator[can.Message]:
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


def _read_blf(path: Path, stats: ReadStats) -> Iterator[can.Message]:
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


def _read_mf4(path: Path, stats: ReadStats) -> Iterator[can.Message]:
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


def first_timestamp(path: str | Path) -> float | None:
    """The timestamp (s; epoch where the format stores absolute times) of a log's first frame.

    This is the log's own clock -- when the logger recorded the frame -- not the data time
    the decoder derives from the sensor's tick.

    Parameters
    ----------
    path : str or Path
        A CAN log of any registered format.

    Returns
    -------
    float or None
        ``None`` for a log without a readable frame.
    """
    for msg in read_log(path):
        return float(msg.timestamp)
    return None


def read_log(path: str | Path, stats: Optional[ReadStats] = None, *,
             channel: Optional[str] = None) -> Iterator[can.Message]:
    """Iterate over the frames of a CAN log (format by suffix), skipping bad lines.

    Parameters
    ----------
    path : str or Path
        ``.log``, ``.asc``, ``.blf``, ``.trc`` or ``.mf4`` (any case).
    stats : ReadStats, optional
        Filled with the number of frames read and lines skipped, and the frames per bus
        channel (``stats.channels``).
    channel : str, optional
        Only the frames of this bus channel, named as the file names it (:func:`channel_wanted`:
        ``"1"`` or ``"CAN1"`` for channel 1 of an ASC, BLF, TRC or MDF4 log, the interface
        name such as ``"can1"`` for candump); the others are counted in
        ``stats.other_channel``. Default: every frame.

    Yields
    ------
    can.Message
        In file order, with the log's timestamps (s; absolute where the format stores them).

    Raises
    ------
    InputError
        Missing or unreadable file, or a file whose header cannot be read.
    UsageError
        Unknown suffix; at the end of the log, a ``channel`` that no frame has (naming the
        channels present).
    """
    p, suf, st = _open_log(path, stats)
    fmt = LOG_FORMATS[suf]
    try:
        return _select_messages(p, suf, fmt.read(p, st), st, channel)
    except InputError:
        raise
    except ImportError as exc:  # asammdf missing
        raise InputError(f"{p}: reading {fmt.name} needs an extra package: {exc}") from None
    except Exception as exc:
        raise InputError(f"{p}: not a readable {fmt.name} file: {type(exc).__name__}: "
                         f"{' '.join(str(exc).split())[:160]}") from None


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


#: python-can's BLF writer stores a start time below this (1990-01-01, epoch s) as no date
#: (``timestamp_to_systemtime``), which its reader then takes as 0
BLF_DATED_FROM = 631152000.0


class _BLFWriter(can.BLFWriter):
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
    fmt = LOG_FORMATS[log_format(p, "output log", compressed=False)]
    try:
        return fmt.write(str(p))
    except ImportError as exc:
        raise InputError(f"{p}: writing {fmt.name} needs an extra package: {exc}") from None
    except OSError as exc:
        raise InputError(f"{p}: cannot create log file: {exc.strerror or exc}") from None


# ---- the registry ----------------------------------------------------------------------------
def _candump_writer(path: str) -> can.io.generic.MessageWriter:
    return can.CanutilsLogWriter(path, channel="can0")


def _candump_batches(path: Path, stats: ReadStats) -> Iterator[LabelledFrames]:
    return _candump_labelled(path, stats)


@dataclass(frozen=True)
class LogFormat:
    """One CAN log format of :data:`LOG_FORMATS`.

    Attributes
    ----------
    name : str
        Human name, for messages and docs.
    read : callable
        ``read(path, stats) -> iterator of can.Message``, tolerant (see the module doc); may
        raise on a file it cannot open as this format (:func:`read_log` reports it).
    write : callable
        ``write(path) -> python-can writer``.
    read_arrays : callable or None
        ``read_arrays(path, stats) -> iterator of LabelledFrames`` (frames with their bus
        channels) where the format has a batch parser; ``None``: :func:`read_log_arrays`
        converts the messages of ``read``.
    """

    name: str
    read: Callable[[Path, ReadStats], Iterator[can.Message]]
    write: Callable[[str], can.io.generic.MessageWriter]
    read_arrays: Optional[Callable[[Path, ReadStats], Iterator[LabelledFrames]]] = None


#: suffix (lower case) -> format: the one table choosing readers and writers, as python-can's
#: ``can.io`` does with its reader and writer tables. Use :func:`is_can_log` or
#: :func:`log_format` rather than a list of suffixes of your own.
#: The suffixes and names are :data:`suspid.can.formats.FORMATS`'s (re-exported here).
LOG_FORMATS: dict[str, LogFormat] = {
    ".log": LogFormat(FORMATS[".log"], _read_candump, _candump_writer, _candump_batches),
    ".asc": LogFormat(FORMATS[".asc"], _read_asc, _ASCWriter),
    ".blf": LogFormat(FORMATS[".blf"], _read_blf, _BLFWriter),
    ".trc": LogFormat(FORMATS[".trc"], _read_trc, can.TRCWriter),
    ".mf4": LogFormat(FORMATS[".mf4"], _read_mf4, can.MF4Writer),
}
