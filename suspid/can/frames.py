"""Batches of CAN frames as NumPy arrays, their bus channels, and what a tolerant reader skipped.

:class:`FrameArrays` is the decoder's vectorized input; :class:`ReadStats` counts frames,
skipped lines and damage; the channel helpers name a frame's bus channel as the log file
names it and select the frames of one channel.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Iterator, Optional, Sequence

import can
import numpy as np

from suspid.can.formats import log_suffix
from suspid.errors import UsageError

#: the file's number of python-can's ``Message.channel`` 0: ASC and BLF count from 1 in the
#: file, python-can from 0; TRC and MDF4 as written; candump names the interface (``can0``)
_CHANNEL_BASE = {".asc": 1, ".blf": 1, ".trc": 0, ".mf4": 0}
#: an option value naming a numbered channel: ``1``, ``CAN1`` (CANedge), ``ch1``, ``channel 1``
_CHANNEL_NUMBER = re.compile(r"(?:can|ch|channel)?\s*(\d+)", re.IGNORECASE)
#: the label of a frame without a channel (an MDF4 file without ``BusChannel``)
NO_CHANNEL = "none"


def channel_label(suffix: str, channel: object) -> str:
    """A frame's bus channel as the log file names it: ``"1"`` for channel 1 of the numbered
    formats (``suffix`` ``.asc``, ...; ``channel`` as python-can's reader gives it), the
    interface name for candump (``"can0"``), :data:`NO_CHANNEL` for none."""
    if channel is None:
        return NO_CHANNEL
    if isinstance(channel, (int, np.integer)) and not isinstance(channel, bool):
        return str(int(channel) + _CHANNEL_BASE.get(suffix, 0))
    return str(channel)


def channel_wanted(suffix: str, text: str) -> str:
    """The channel label (:func:`channel_label`) that an option value names in a log:
    ``1``, ``CAN1``, ``ch1``, ``channel 1`` name channel 1; for candump the interface name."""
    text = text.strip()
    if suffix == ".log":
        return text
    m = _CHANNEL_NUMBER.fullmatch(text)
    return str(int(m.group(1))) if m else text


def describe_channels(counts: dict[str, int]) -> str:
    """``"1 (1200 frames), 2 (1200 frames)"``, or ``"no frames"`` for a log without any."""
    return ", ".join(f"{ch} ({n} frames)" for ch, n in counts.items()) or "no frames"


#: frame keys (CAN ID | extended flag << 31) below ``_KEY_SPAN`` are counted per channel as
#: one int64 ``code << _KEY_BITS | key``
_KEY_BITS = 40
_KEY_SPAN = 1 << _KEY_BITS


@dataclass
class ReadStats:
    """What a tolerant reader read and skipped.

    ``malformed`` counts the lines or records skipped (``examples``: the first few,
    ``file:line: reason``); ``truncated``: a binary file ended inside a record, ``damage``
    naming where (counted once in ``malformed``); ``channels``: per bus channel
    (:func:`channel_label`), frame key (CAN ID, bit 31 for extended) -> frames;
    ``other_channel``: frames of other channels than the one asked for, skipped.
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
        # numbered channels in numeric order, then names
        return dict(sorted(out.items(), key=lambda kv: (0, int(kv[0]), "") if kv[0].isdigit()
                           else (1, 0, kv[0])))

    def damaged(self, path: Path, what: str) -> None:
        """Record the damage of a binary file (the first one named): truncated, one record
        counted ``malformed``."""
        self.truncated = True
        if not self.damage:
            self.malformed += 1
            self.damage = f"{path}: damaged {log_suffix(path)[1:].upper()} file: {what}"

    def bad(self, where: str, reason: str) -> None:
        """Count one skipped line/record and keep the first five reasons."""
        self.malformed += 1
        if len(self.examples) < 5:
            self.examples.append(f"{where}: {' '.join(reason.split())[:120]}")


@dataclass
class FrameArrays:
    """A batch of CAN frames as parallel NumPy arrays (the decoder's vectorized input).

    Per frame: ``timestamp`` (s), ``arbitration_id`` (without the extended flag),
    ``is_extended``, ``frame_type`` (error or remote frame: no data), ``length`` (bytes) and
    ``data`` (N, 8) uint8, zero beyond ``length``; frames over 8 bytes (CAN FD) hold their
    whole payload in ``long_data`` (row -> bytes).
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
    def empty(cls, n: int = 0) -> "FrameArrays":
        """A batch of ``n`` frames of zeros."""
        return cls(np.zeros(n), np.zeros(n, np.int64), np.zeros(n, bool), np.zeros(n, bool),
                   np.zeros(n, np.int64), np.zeros((n, 8), np.uint8))

    def put(self, at: np.ndarray, src: "FrameArrays") -> None:
        """Write the frames of ``src`` into rows ``at``."""
        for name in ("timestamp", "arbitration_id", "is_extended", "frame_type", "length", "data"):
            getattr(self, name)[at] = getattr(src, name)
        for j, payload in src.long_data.items():
            self.long_data[int(at[j])] = payload

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
        return self.long_data.get(i) or self.data[i, :int(self.length[i])].tobytes()

    def iter_messages(self, channels: Sequence[str], codes: np.ndarray) -> Iterator[can.Message]:
        """The frames as python-can messages (error and remote frames as error frames, over 8
        bytes as CAN FD), with ``channels[codes[i]]`` as frame ``i``'s channel."""
        ts = self.timestamp.tolist()
        ids = self.arbitration_id.tolist()
        ext = self.is_extended.tolist()
        ft = self.frame_type.tolist()
        lens = self.length.tolist()
        raw = np.ascontiguousarray(self.data).tobytes()
        chan = [channels[c] for c in np.broadcast_to(codes, (len(ts),)).tolist()]
        long_data = self.long_data
        Message = can.Message
        for i in range(len(ts)):
            got = long_data.get(i) if long_data else None
            data = bytearray(raw[8 * i:8 * i + min(lens[i], 8)] if got is None else got)
            yield Message(timestamp=ts[i], arbitration_id=ids[i], is_extended_id=ext[i],
                          is_error_frame=ft[i], data=data, channel=chan[i],
                          is_fd=lens[i] > 8, check=False)

#: a batch of frames with each frame's channel: ``(frames, codes, names)``, ``names[codes[i]]``
#: the channel label (:func:`channel_label`) of frame ``i``
LabelledFrames = tuple[FrameArrays, np.ndarray, list[str]]


def _missing_channel(path: Path, channel: str, stats: ReadStats) -> UsageError:
    """The one-line error of a channel option naming no channel of the log."""
    return UsageError(f"{path}: can.channel {channel}: no such channel in the log; "
                      f"channels present: {describe_channels(stats.channel_frames())}")


def select_arrays(path: Path, suf: str, chunks: Iterator[LabelledFrames], st: ReadStats,
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


def select_messages(path: Path, suf: str, messages: Iterator[can.Message], st: ReadStats,
                     channel: Optional[str]) -> Iterator[can.Message]:
    """:func:`select_arrays` for messages."""
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

