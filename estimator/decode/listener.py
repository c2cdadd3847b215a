"""The estimator's CAN front end: a python-can Listener that validates, decodes and buffers.

Every frame goes through, in order (the first failing check names the rejection reason):

==================  ====================================================================
reason              check
==================  ====================================================================
``frame_type``      error and remote frames carry no data
``time``            the frame's timestamp is earlier than the last accepted frame's,
                    or is not finite (NaN, inf)
``unknown_id``      the CAN ID is not a message of the DBC (foreign traffic)
``dlc``             payload length differs from the DBC's message length
``crc``             E2E CRC-8 J1850 mismatch (corrupted payload, wrong ID)
``counter_stale``   alive counter repeated or older (duplicate / out-of-order frame)
``counter_jump``    counter advanced by more than ``max_counter_delta`` (too many frames
                    lost to trust the sequence) or is the invalid value 15; the frame
                    re-synchronises the sequence, as in AUTOSAR E2E profile 1
``no_sync``         ``time_source="tick"`` and no ``SN_Sync`` frame received yet, or none
                    since this message's last frame after a silence longer than 7
                    periods (a link reopened: the last tick is stale)
==================  ====================================================================

Frames of DBC messages that carry none of the mapped channels are counted as ``ignored``
(not decoded); an advance of 2..``max_counter_delta`` is accepted and its missing frames are
counted as ``lost``. Lines a log reader could not parse arrive as ``malformed`` through
:meth:`DecodeListener.count_malformed`. Nothing is fatal: a bad frame is counted and dropped.

Accepted frames are decoded with the precompiled :class:`suspid.can.codec.MessageCodec`
(equal to cantools, several times faster), mapped onto model channels (a signal whose
``<Name>Valid`` bit is 0 becomes NaN) and written with their data time into a
:class:`~estimator.decode.buffer.RollingBuffer`. Data time is the frame timestamp
(``time_source="timestamp"``: logs, and buses that timestamp on reception), or the sensor
node's sample tick (``time_source="tick"``: ``Tick * PeriodUs`` of the last ``SN_Sync``,
matched through the frame's counter -- exact whatever the transport's latency and
``--speed``; use it for SLCAN, whose host-side timestamps are arrival times). In tick mode
the loss rules (counter advance vs time since the last frame) use that data time too.
``time_source="auto"`` takes the sensor clock whenever the stream carries one: the tick
once an ``SN_Sync`` frame is among the first frames (up to ``AUTO_FRAMES`` frames of the
DBC's messages are held until one comes; foreign frames do not count), the timestamps otherwise (a foreign stream, or a DBC without
``SN_Sync``). :attr:`DecodeListener.time_source` then names the base taken, and
:meth:`DecodeListener.frame_stats` reports it as ``time_base``.

Feed it like any python-can listener: ``can.Notifier(bus, [listener])`` on a live bus, or
:func:`estimator.decode.replay.feed_log` for a log (no reader thread and queue hand-off, so
replay runs at decode speed and is deterministic; :class:`estimator.decode.replay.ReplayBus`
runs the same log through a Notifier).

Batches
-------
Frames are validated and decoded in batches. ``on_message_received`` only queues the
message (a few hundred ns); the queue is processed when ``batch_size`` frames are waiting,
when a ``SUSPID_Alert`` frame arrives (so ``on_alert`` is called at once), and before
anything reads the listener's results -- ``counts``, ``frame_stats()``, ``aligned()``,
``buffer`` and its rings, ``node_status``, ``alerts``, ``period``... -- so a reader always
sees every frame received so far and callers need not know about the queue
(:meth:`DecodeListener.flush` does it explicitly). :meth:`DecodeListener.feed_arrays` takes
frames already in arrays (:class:`suspid.can.logs.FrameArrays`, e.g. from the candump
array reader) and skips the messages altogether.

A batch is processed with NumPy: the stateless checks (frame type, ID, DLC, E2E CRC-8 by
table lookups over the byte columns) for all frames at once; the time check as one
comparison of each timestamp with the previous one; per message, the alive counters and
the period estimate (one short Python loop per message, a float recurrence that must stay
bit-exact); the signals of the accepted frames decoded column-wise
(:mod:`estimator.decode.vector`) and stored with :meth:`RollingBuffer.push_many`. Whatever a
batch holds that the array code does not cover -- a timestamp going back, NaN or inf, a
counter that does not advance by exactly one, a silence, a CAN FD payload, a message
without an array decoder -- is handed to the frame-by-frame code it replaced, from that
frame on (per message for counter anomalies, for every message for time anomalies), and
the batch resumes after it. Counters (by reason, lost), buffer contents (bit for bit),
per-message state and the SN_Sync/SN_Status/alert state are identical to the
frame-by-frame path (``batch_size=0``) in both time sources -- property-tested in
``tests/can/test_batch_equivalence.py`` on valid node streams with drops, bursts, bit
flips, duplicates, reordering, foreign IDs, wrong DLCs, clocks going back and counter
resets.
"""
from __future__ import annotations

import copy
import math
import sys
import threading
from bisect import bisect_left
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Literal, Sequence, Union, cast

import can
import numpy as np
from cantools.database.can import Database, Message

from estimator.decode.buffer import Aligned, RollingBuffer, Source
from estimator.decode.vector import RowsFn, compile_raw, compile_vector_row
from suspid.can.codec import MessageCodec, decode_alert, signal_spec
from suspid.can.crc import COUNTER_MODULUS, TABLE_NP as _CRC_TABLE, data_id_register, make_e2e_checker
from suspid.can.logs import FrameArrays
from suspid.can.dbc import (ALERT_MESSAGE, STATUS_MESSAGE, SYNC_MESSAGE, find_message, is_e2e,
                            load_dbc)
from suspid.can.signal_map import SignalMap, SignalMapLike, SignalMapping, as_signal_map
from suspid.errors import UsageError
from suspid.models import SuspensionModel, get_model

#: rejection reasons, in check order
REJECT_REASONS: tuple[str, ...] = ("malformed", "frame_type", "time", "unknown_id", "dlc", "crc",
                                   "counter_stale", "counter_jump", "no_sync")
_EXT = 1 << 31
_INF = math.inf
#: consecutive 'time' rejections after which the time base is re-anchored (a clock reset)
TIME_RESYNC = 16
#: ``time_source="auto"``: frames held while waiting for an ``SN_Sync`` before the time base
#: falls back to the frame timestamps (the node sends SN_Sync with every sample)
AUTO_FRAMES = 64
#: frames waiting before ``on_message_received`` processes the queue (default batch size)
BATCH_SIZE = 2048
#: default ``min_batch``: fewer frames than this are validated one by one (below it the
#: array code's fixed cost, ~100 NumPy calls, exceeds the per-frame path's)
SMALL_BATCH = 192
#: default ``min_run``: a run between two time anomalies shorter than this goes frame by frame
MIN_RUN = 192
#: the period estimate cannot trigger the silence rule while every interval stays below
#: 1.5 x (1 - 1e-9) x the smallest of the estimate and the intervals so far (the estimate
#: is a convex combination of them; the margin covers its rounding over 1e5+ updates)
_SILENCE_SAFE = 1.5 * (1.0 - 1e-9)

_DATA, _SYNC, _STATUS, _ALERT = range(4)
#: stateless outcome of a frame in a batch (0: passed ID, DLC and CRC)
_O_UNKNOWN, _O_IGNORED, _O_DLC, _O_CRC = 1, 2, 3, 4


#: a frame payload (python-can gives ``bytearray``, the batch path ``bytes``)
Payload = Union[bytes, bytearray]
#: payload -> decoded values
Unpack = Callable[[Payload], tuple]


def _any_buffer(unpack: Callable[[bytes], tuple]) -> Unpack:
    """A :class:`MessageCodec` unpacker as a payload decoder.

    The codec types its compiled unpackers for ``bytes``; they unpack with ``struct`` (or
    cantools), which take any buffer, ``bytearray`` included.
    """
    return cast(Unpack, unpack)


def _decoded_elsewhere(data: Payload) -> tuple:
    """``decode`` of routes never decoded by it: data messages (``row``/``vrow``) and
    SUSPID_Alert (:func:`~suspid.can.codec.decode_alert`)."""
    return ()


@dataclass(eq=False)
class _Route:
    """How to validate and store one CAN ID."""

    name: str
    kind: int
    dlc: int
    check: Callable[[Payload], bool] | None   # E2E CRC checker, None if not protected
    decode: Unpack                             # special messages
    source: Source | None = None
    row: Unpack | None = None   # data messages: payload -> channel values
    last_c: int = -1
    last_ts: float = 0.0
    period: float = 0.0
    accepted: int = 0
    last_arrival: float = 0.0   # tick mode: frame timestamp (arrival) of the last frame
    sync_n: int = -1            # tick mode: SN_Sync frames seen at the last frame
    key: int = 0                # CAN ID | extended flag
    start_reg: int = 0          # E2E CRC register after the data-ID bytes
    vrow: RowsFn | None = None  # data messages: array decoder (None: decode frame by frame)
    vsync: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None  # Tick, PeriodUs


def _compile_row(msg: Message, maps: Sequence[SignalMapping]) -> Unpack:
    """``row(payload) -> (value per mapping, ...)``: decode, validity bit, scale and offset.

    The values come from one :class:`MessageCodec` decode (a ``struct`` unpack for our DBC);
    a ``<Signal>Valid`` bit, when the DBC has one, turns the value into NaN when 0.
    """
    names = list(dict.fromkeys(m.signal for m in maps))
    codec = MessageCodec(msg, names)
    ns: dict[str, object] = {"_dec": codec.decode, "nan": math.nan}
    terms = []
    for j, m in enumerate(maps):
        term = f"v[{names.index(m.signal)}]"
        if m.scale != 1.0:
            term = f"{term} * {float(m.scale)!r}"
        if not m.remove_mean and float(m.offset) != 0.0:
            term = f"{term} + {float(m.offset)!r}"
        vname = f"{m.signal}Valid"
        if any(x.name == vname for x in msg.signals):
            spec = signal_spec(msg, vname)
            if spec.length == 1 and not spec.big_endian:
                cond = f"data[{spec.start >> 3}] >> {spec.start & 7} & 1"
            else:
                ns[f"_vd{j}"] = MessageCodec(msg, [vname]).unpack_raw
                cond = f"_vd{j}(data)[0]"
            term = f"({term} if {cond} else nan)"
        terms.append(term)
    code = ("def _row(data, _dec=_dec, nan=nan):\n"
            "    v = _dec(data)\n"
            f"    return ({', '.join(terms)},)\n")
    exec(code, ns)  # noqa: S102 - generated from the DBC layout and numeric map entries
    return cast(Unpack, ns["_row"])   # defined by the exec above


@dataclass
class FrameCounts:
    """Counters of the listener (see the module docstring)."""

    accepted: int = 0
    ignored: int = 0
    lost: int = 0
    rejected: dict[str, int] = field(default_factory=lambda: dict.fromkeys(REJECT_REASONS, 0))


def model_channels(model: SuspensionModel) -> list[str]:
    """Every channel a map may target: measured channels, roads and road velocities."""
    return list(model.channels) + list(model.roads) + [f"{r}_dot" for r in model.roads]


class DecodeListener(can.Listener):
    """Validate, decode and buffer the frames of a suspension sensor bus.

    Parameters
    ----------
    model : str or SuspensionModel
        Which channels to extract (``quarter2`` -> x1, x2, r, ...).
    dbc : str, Path or cantools Database, optional
        Default suspid's ``suspension.dbc``.
    signal_map : SignalMap, path or list of str, optional
        ``channel = MESSAGE.SIGNAL`` mappings; default the DBC's ``SuspidChannel``
        attributes (suspid's DBC). Required for a foreign DBC.
    capacity : int
        Rows per message in the rolling buffer.
    growable : bool
        Grow the buffer instead of overwriting (offline loading of a whole log).
    time_source : {"timestamp", "tick", "auto"}
        Data time from the frame timestamps, from the node's ``SN_Sync`` tick, or from the
        tick when the stream carries ``SN_Sync`` frames and the timestamps otherwise.
    max_counter_delta : int
        Largest accepted counter advance (1 = no frame may be lost).
    stale_window : int
        Counter steps back still read as an old (late or duplicate) frame rather than a jump.
    batch_size : int
        Frames queued by :meth:`on_message_received` before they are processed as one
        batch (any read of the results processes the queue first). ``0`` validates and
        decodes every frame on arrival, one by one (the reference path; same results).
    on_alert : callable, optional
        Called with each accepted ``SUSPID_Alert`` (the dict appended to ``alerts``), in
        order, as soon as the frame is received (an alert frame flushes the queue).

    Attributes
    ----------
    counts : FrameCounts
    buffer : RollingBuffer
    node_status : dict
        Last ``SN_Status`` (state, sample_rate, fault_flags, busoff_count, sensor_set, t).
    alerts : list of dict
        ``SUSPID_Alert`` frames seen (model, parameter, value, nominal, severity, t).
    period : float or None
        Sample period (s) announced by ``SN_Sync``.
    mean_channels : list of str
        Channels whose map subtracts the data's mean (applied at alignment).
    frames : int
        Frames received (queued ones included).
    time_resyncs : int
        Times the time base was re-anchored after a clock reset.
    min_batch : int
        Batches smaller than this are validated frame by frame (tuning; same results).
    min_run : int
        Runs of frames between time anomalies shorter than this go frame by frame (tuning;
        same results).
    """

    def __init__(self, model: str | SuspensionModel, dbc: str | Path | Database | None = None,
                 signal_map: SignalMapLike = None, *, capacity: int = 1 << 16,
                 growable: bool = False,
                 time_source: Literal["timestamp", "tick", "auto"] = "timestamp",
                 max_counter_delta: int = 4, stale_window: int = 5,
                 batch_size: int = BATCH_SIZE,
                 on_alert: Callable[[dict[str, object]], None] | None = None) -> None:
        self.model = get_model(model) if isinstance(model, str) else model
        smap = as_signal_map(signal_map)
        if isinstance(dbc, Database):
            db = dbc
        else:
            path = dbc if dbc is not None else (smap.dbc if smap is not None else None)
            db = load_dbc(path)
        self.db = db
        if smap is None:
            smap = SignalMap.from_dbc(db, self.model.name)
            if not smap.mappings:
                raise UsageError(f"{getattr(db, 'suspid_path', 'the DBC')} declares no channel of "
                                 f"model {self.model.name} (no SuspidChannel attributes); give a "
                                 "signal map, e.g. --map x1_ddot=MESSAGE.SIGNAL")
        smap.validate(db, model_channels(self.model))
        self.signal_map = smap
        if time_source not in ("timestamp", "tick", "auto"):
            raise UsageError(f"time_source must be 'timestamp', 'tick' or 'auto', "
                             f"got {time_source!r}")
        self._auto = time_source == "auto"
        #: the time source asked for ("auto" keeps its name here once decided)
        self.time_source_requested = time_source
        self.time_source = "timestamp" if self._auto else time_source
        if not 1 <= max_counter_delta <= COUNTER_MODULUS - 2:
            raise UsageError(f"max_counter_delta must be 1..13, got {max_counter_delta}")
        if batch_size < 0:
            raise UsageError(f"batch_size must be >= 0, got {batch_size}")
        self.max_counter_delta = max_counter_delta
        self.stale_window = max(0, min(stale_window, COUNTER_MODULUS - 1 - max_counter_delta))
        self._buffer = RollingBuffer(capacity, growable)
        self._counts = FrameCounts()
        self._node_status: dict[str, object] = {}
        self._alerts: list[dict[str, object]] = []
        self._period: float | None = None
        self.mean_channels = [m.channel for m in smap.mappings if m.remove_mean]
        self._frames = 0
        self._time_resyncs = 0
        self._last_ts = -sys.float_info.max  # any finite time passes the first check
        self._time_rejects = 0
        self._sync_tick: int | None = None
        self._sync_n = 0
        self._routes: dict[int, _Route] = {}
        self._known: set[int] = set()
        self._rejected = self._counts.rejected
        self._tick_time = time_source == "tick"
        #: live reception's own counters (frames read, lost by cause), set by the receiver
        self.receive_stats: dict[str, object] = {}
        self._build_routes()
        # ---- batching
        self.batch_size = batch_size
        self.min_batch = SMALL_BATCH
        self.min_run = MIN_RUN
        self.on_alert = on_alert
        self._lock = threading.RLock()         # one batch (or frame) processed at a time
        self._pending: deque[can.Message] = deque()
        self._outbox: list[dict[str, object]] = []   # accepted alerts for on_alert
        self._prompt = frozenset(r.key & ~_EXT for r in self._routes.values() if r.kind == _ALERT)
        self._buffer.before_read = self.flush
        self._known_ids = np.array(sorted(k & ~_EXT for k in self._known), dtype=np.int64)
        self._sync_ids = frozenset(r.key & ~_EXT for r in self._routes.values() if r.kind == _SYNC)
        if not self._sync_ids:
            self._auto = False   # no SN_Sync in the DBC: the timestamps are the only clock
        if batch_size == 0:
            # the per-frame entry bound once, not dispatched per frame (mypy forbids assigning
            # to a method; the signatures are the same)
            self.on_message_received = self._on_message_now  # type: ignore[method-assign]
        elif on_alert is None:
            self.on_message_received = self._queue  # type: ignore[method-assign]  # as above

    # ---- setup -----------------------------------------------------------------------
    def _key(self, frame_id: int, extended: bool) -> int:
        return frame_id | (_EXT if extended else 0)

    def _build_routes(self) -> None:
        db = self.db
        for msg in db.messages:
            self._known.add(self._key(msg.frame_id, msg.is_extended_frame))
        per_msg: dict[str, list] = {}
        for m in self.signal_map.mappings:
            msg = find_message(db, m.message, self.signal_map.source)
            per_msg.setdefault(msg.name, []).append(m)
        for name, maps in per_msg.items():
            msg = db.get_message_by_name(name)
            src = self._buffer.source(name, [m.channel for m in maps])
            route = self._add_route(msg, _DATA, _decoded_elsewhere, src, _compile_row(msg, maps))
            route.vrow = compile_vector_row(msg, maps)
        for special, kind in ((SYNC_MESSAGE, _SYNC), (STATUS_MESSAGE, _STATUS),
                              (ALERT_MESSAGE, _ALERT)):
            try:
                msg = db.get_message_by_name(special)
            except KeyError:
                continue
            if self._key(msg.frame_id, msg.is_extended_frame) in self._routes:
                continue
            if kind == _SYNC:
                codec = MessageCodec(msg, ["Tick", "PeriodUs"])
                dec = _any_buffer(codec.decode)
                route = self._add_route(msg, kind, dec)
                route.vsync = _compile_sync(codec)
                continue
            if kind == _STATUS:
                dec = _any_buffer(MessageCodec(msg, ["State", "SampleRate", "FaultFlags",
                                                     "BusOffCount", "SensorSet"]).decode)
            else:
                dec = _decoded_elsewhere  # decode_alert, with cantools (multiplexed, rare)
            self._add_route(msg, kind, dec)
        if self.time_source == "tick" and not any(r.kind == _SYNC for r in self._routes.values()):
            raise UsageError(f"time_source 'tick' needs message {SYNC_MESSAGE} in the DBC "
                             f"{getattr(self.db, 'suspid_path', '')}")
        # batch path: the routes numbered SN_Sync first, then the E2E-protected ones (the
        # frames of a batch are grouped in this order), a sorted key table for the lookup
        # and per-route arrays of what the stateless checks need
        self._route_list = sorted(self._routes.values(),
                                  key=lambda r: (r.kind != _SYNC, r.check is None))
        rl = self._route_list
        order = sorted(range(len(rl)), key=lambda i: rl[i].key)
        self._rkeys = np.array([rl[i].key for i in order], dtype=np.int64)
        self._rnum = np.array(order, dtype=np.int64)
        self._ikeys = np.array(sorted(self._known - set(self._routes)), dtype=np.int64)
        self._rdlc = np.array([r.dlc for r in rl], dtype=np.int64)
        self._re2e = np.array([r.check is not None for r in rl], dtype=bool)
        self._rstart = np.array([r.start_reg for r in rl], dtype=np.uint8)
        self._rdata_e2e = np.array([r.kind == _DATA and r.check is not None for r in rl])

    def _add_route(self, msg: Message, kind: int, decode: Unpack,
                   source: Source | None = None, row: Unpack | None = None) -> _Route:
        check = make_e2e_checker(msg.frame_id, msg.length) if is_e2e(msg) else None
        route = _Route(msg.name, kind, msg.length, check, decode, source, row)
        route.key = self._key(msg.frame_id, msg.is_extended_frame)
        route.start_reg = data_id_register(msg.frame_id) if check is not None else 0
        self._routes[route.key] = route
        return route

    # ---- reception -------------------------------------------------------------------
    def on_message_received(self, msg: can.Message) -> None:
        """Queue one frame; the queue is validated, decoded and buffered as one batch.

        The frame's fields are read when the batch is processed (at the latest when anything
        reads the results), as python-can's ``BufferedReader`` keeps messages: do not modify
        a message after handing it over.
        """
        pend = self._pending
        pend.append(msg)
        if len(pend) >= self.batch_size or msg.arbitration_id in self._prompt:
            self.flush()

    def _queue(self, msg: can.Message) -> None:
        """:meth:`on_message_received` without ``on_alert`` (no prompt flush needed)."""
        pend = self._pending
        pend.append(msg)
        if len(pend) >= self.batch_size:
            self.flush()

    def _on_message_now(self, msg: can.Message) -> None:
        """``batch_size=0``: validate one frame on arrival (the frame-by-frame path)."""
        if self._auto:
            self._pending.append(msg)
            self.flush()
            return
        with self._lock:
            self._scalar_msg(msg)
        if self._outbox:
            self._deliver()

    def choose_time_base(self, ids: Any, final: bool = False) -> bool:
        """``time_source="auto"``: take the tick if ``ids`` hold an SN_Sync frame, the
        timestamps once ``AUTO_FRAMES`` frames (or the end of the input) came without one.

        Parameters
        ----------
        ids : array_like of int
            CAN IDs of the first frames.
        final : bool
            Decide now even with fewer than ``AUTO_FRAMES`` frames.

        Returns
        -------
        bool
            True when the base is decided.
        """
        if not self._auto:
            return True
        arr = np.asarray(ids, dtype=np.int64) & ~_EXT
        if np.isin(arr, list(self._sync_ids)).any():
            self.time_source, self._tick_time = "tick", True
        elif not (final or int(np.isin(arr, self._known_ids).sum()) >= AUTO_FRAMES):
            return False   # foreign traffic does not count: only frames of the DBC decide
        self._auto = False
        return True

    def sync_first_index(self, ids: Any) -> int:
        """Tick base, start of a stream: where the first ``SN_Sync`` frame lies among the
        first frames ``ids`` (-1: none, or not the start of a stream).

        Frames of the first sample that arrived before its ``SN_Sync`` (arrival jitter) have
        no tick yet; the callers move that SN_Sync to the front, with the first frame's
        arrival time, so they are placed in their sample instead of rejected (``no_sync``).
        """
        c = self._counts
        if not self._tick_time or self._sync_tick is not None or \
                c.accepted + c.ignored + sum(c.rejected.values()) > 0:
            return -1
        arr = np.asarray(ids, dtype=np.int64)[:AUTO_FRAMES] & ~_EXT
        hit = np.flatnonzero(np.isin(arr, list(self._sync_ids)))
        return int(hit[0]) if hit.size else -1

    def finish(self) -> None:
        """The input has ended: process every held frame (see ``time_source="auto"``)."""
        with self._lock:
            if self._auto:
                self.choose_time_base([m.arbitration_id for m in self._pending], final=True)
        self.flush()

    def flush(self) -> None:
        """Validate, decode and buffer every queued frame (readers call it implicitly).

        Also waits for a batch another thread (a ``can.Notifier``) is processing, so a
        reader never sees half a batch. With ``time_source="auto"`` frames stay queued
        until the time base is decided (:meth:`finish` decides it at the end of an input).
        """
        with self._lock:
            pend = self._pending
            if self._auto:
                if not self.choose_time_base([m.arbitration_id for m in pend], False):
                    return
                k = self.sync_first_index([m.arbitration_id for m in pend])
                if k > 0:
                    first = copy.copy(pend[k])
                    first.timestamp = pend[0].timestamp
                    del pend[k]
                    pend.appendleft(first)
            n = len(pend)
            if n:
                msgs = [pend.popleft() for _ in range(n)]
                fa = None
                if n >= self.min_batch:
                    try:
                        fa = FrameArrays.from_messages(msgs)
                    except (TypeError, ValueError, OverflowError):
                        fa = None   # odd field types: the frame-by-frame path handles them
                if fa is None:
                    for msg in msgs:
                        self._scalar_msg(msg)
                else:
                    self._process(fa, 0, n)
        if self._outbox:
            self._deliver()

    def feed_arrays(self, frames: FrameArrays, start: int = 0, stop: int | None = None) -> int:
        """Validate, decode and buffer frames given as arrays (after any queued message).

        Parameters
        ----------
        frames : FrameArrays
            E.g. a chunk of :func:`suspid.can.logs.read_log_arrays`.
        start, stop : int
            The rows to take (default all).

        Returns
        -------
        int
            Frames taken.
        """
        stop = len(frames) if stop is None else min(stop, len(frames))
        if stop <= start:
            return 0
        if self._auto:
            with self._lock:
                self.choose_time_base(
                    np.concatenate([np.array([m.arbitration_id for m in self._pending], np.int64),
                                    np.asarray(frames.arbitration_id[start:stop], np.int64)]),
                    final=True)
        self.flush()
        with self._lock:
            self._process(frames, start, stop)
        if self._outbox:
            self._deliver()
        return stop - start

    def feed_messages(self, messages: Sequence[can.Message]) -> int:
        """Validate, decode and buffer a sequence of messages as batches; returns how many."""
        self.flush()
        n = len(messages)
        step = 1 << 16
        for lo in range(0, n, step):
            part = messages[lo:lo + step]
            for msg in part:
                self._pending.append(msg)
            self.flush()
        return n

    def _deliver(self) -> None:
        """Hand accepted alerts to ``on_alert`` (outside the processing lock)."""
        with self._lock:
            out, self._outbox = self._outbox, []
        if self.on_alert is not None:
            for alert in out:
                self.on_alert(alert)

    # ---- the frame-by-frame path ---------------------------------------------------------
    def _scalar_msg(self, msg: can.Message) -> None:
        """Validate one python-can message (caller holds the lock)."""
        self._frames += 1
        if msg.is_error_frame or msg.is_remote_frame:
            self._rejected["frame_type"] += 1
            return
        self._validate(msg.timestamp, msg.arbitration_id | _EXT if msg.is_extended_id
                       else msg.arbitration_id, msg.data)

    def _validate(self, ts: float, key: int, data: bytes | bytearray) -> None:
        """Every check after the frame type, decode and buffer (one frame; the reference)."""
        rejected = self._rejected
        if not self._last_ts <= ts < _INF:  # one chained compare: backwards, NaN or inf
            if not -_INF < ts < _INF:
                rejected["time"] += 1  # NaN/inf: never a data time, never a re-anchor
                return
            self._time_rejects += 1
            if self._time_rejects < TIME_RESYNC:
                rejected["time"] += 1
                return
            self._time_resyncs += 1  # the clock was reset: re-anchor on this frame
        self._time_rejects = 0
        self._last_ts = ts
        route = self._routes.get(key)
        if route is None:
            if key in self._known:
                self._counts.ignored += 1
            else:
                rejected["unknown_id"] += 1
            return
        if len(data) != route.dlc:
            rejected["dlc"] += 1
            return
        c = -1
        if route.check is not None:
            if not route.check(data):
                rejected["crc"] += 1
                return
            c = data[1] & 0x0F
            last = route.last_c
            arrival = ts
            if self._tick_time:
                # the gap rules below need data time: a host's arrival times bunch (a
                # serial reader hands over a chunk of frames at once), which made the
                # period estimate tiny and counted thousands of frames 'lost'
                if route.kind == _SYNC:
                    tick, period_us = route.decode(data)
                    if period_us > 0:
                        ts = int(tick) * period_us / 1e6   # the exact decimal time
                elif route.kind == _DATA and self._sync_tick is not None and self._period:
                    if (route.sync_n == self._sync_n and last >= 0
                            and arrival - route.last_arrival
                            > COUNTER_MODULUS // 2 * max(route.period, self._period)):
                        # no SN_Sync since this message's last frame, and a silence longer
                        # than the counter can match (a link closed and reopened): the last
                        # tick is stale and would place the frame in the past
                        rejected["no_sync"] += 1
                        return
                    d = (self._sync_tick - c) % COUNTER_MODULUS
                    tick = self._sync_tick - d if d <= COUNTER_MODULUS // 2 else \
                        self._sync_tick - d + COUNTER_MODULUS
                    ts = round(tick * self._period * 1e6) / 1e6   # as SN_Sync's: PeriodUs is an integer
                route.last_arrival = arrival
                route.sync_n = self._sync_n
            if not self._step_counter(route, c, ts):
                return
        if route.kind == _DATA:
            if self._tick_time:
                if self._sync_tick is None or c < 0:
                    rejected["no_sync"] += 1
                    return
                # ts is the data time matched through the counter above
            if route.source is None or route.row is None:   # every _DATA route has both
                raise RuntimeError(f"data route {route.name} without a source or decoder")
            route.source.push(ts, route.row(data))
        elif not self._special(route, data, ts):
            return
        route.accepted += 1
        self._counts.accepted += 1

    def _step_counter(self, route: _Route, c: int, t: float) -> bool:
        """Counter continuity of one frame at time ``t`` (caller holds the lock).

        The next counter value is accepted and updates the frame period; after a silence
        an advance of 1 mod 15 means 15, 30, ... frames were lost that the 4-bit counter
        cannot show (bus-off, burst) -- the time can, so they are counted in ``lost``. Any
        other value goes to :meth:`_counter_gap`. Returns ``False`` if the frame is
        rejected (counted there).
        """
        last = route.last_c
        if last >= 0 and (c - last) % COUNTER_MODULUS != 1:
            if not self._counter_gap(route, c, last, t):
                return False
        elif last >= 0:
            el = t - route.last_ts
            per = route.period
            if per > 0 and el > 1.5 * per:
                steps = int(el / per + 0.5)
                if steps % COUNTER_MODULUS == 1:
                    self._counts.lost += steps - 1
            elif el > 0:
                route.period = el if per <= 0 else 0.9 * per + 0.1 * el
        route.last_c = c
        route.last_ts = t
        return True

    def _counter_gap(self, route: _Route, c: int, last: int, ts: float) -> bool:
        """Counter did not advance by one: accept (lost frames) or reject; ``True`` = accept."""
        rejected = self._rejected
        if c == 15:
            rejected["counter_jump"] += 1
            return False
        delta = (c - last) % COUNTER_MODULUS
        # a 4-bit counter cannot tell 11 lost frames from a frame 4 steps old, nor 2 lost
        # frames from 17; the time since the last frame of this ID can: a gap whose length
        # in periods matches the counter advance is counted from the time
        steps = int((ts - route.last_ts) / route.period + 0.5) if route.period > 0 else 0
        if 2 <= delta <= self.max_counter_delta:
            matched = steps > delta and (steps - delta) % COUNTER_MODULUS == 0
            self._counts.lost += (steps if matched else delta) - 1
            return True
        if steps >= 2 and (steps - delta) % COUNTER_MODULUS == 0:
            self._counts.lost += steps - 1
            return True
        if delta == 0 or delta >= COUNTER_MODULUS - self.stale_window:
            # an old or repeated frame arrives close to the newest one; after a silence of
            # more than a counter cycle it is a restarted sender (node reboot): re-sync
            if not (route.period > 0 and ts - route.last_ts > COUNTER_MODULUS * route.period):
                rejected["counter_stale"] += 1
                return False
        route.last_c = c  # E2E profile 1: the sequence restarts from this frame
        route.last_ts = ts
        rejected["counter_jump"] += 1
        return False

    def _special(self, route: _Route, data: bytes | bytearray, ts: float) -> bool:
        """SN_Sync, SN_Status and SUSPID_Alert frames; ``False`` if rejected."""
        if route.kind == _SYNC:
            tick, period_us = route.decode(data)
            self._sync_tick = int(tick)
            self._sync_n += 1
            if period_us > 0:
                self._period = period_us * 1e-6
        elif route.kind == _STATUS:
            state, rate, flags, busoff, sset = route.decode(data)
            self._node_status = {"t": ts, "state": int(state), "sample_rate": float(rate),
                                 "fault_flags": int(flags), "busoff_count": int(busoff),
                                 "sensor_set": int(sset)}
        else:
            try:
                alert = decode_alert(self.db, data)
            except Exception:  # an unknown ParamKind: a corrupted but CRC-valid alert
                self._rejected["crc"] += 1
                return False
            alert["t"] = ts
            self._alerts.append(alert)
            if self.on_alert is not None:
                self._outbox.append(alert)
        return True

    # ---- the batch path ------------------------------------------------------------------
    def _process(self, fa: FrameArrays, lo: int, hi: int) -> None:
        """Frames ``lo:hi`` of ``fa``, as the frame-by-frame path would (caller holds the lock).

        The stateless checks (frame type, ID, DLC, E2E CRC) are done for the whole batch;
        their counts are taken per segment because a frame rejected for its time is
        counted as ``time`` only. The time check is the state every frame shares: runs
        of frames that pass it (each timestamp finite and not earlier than the previous
        frame's) are processed as one segment (:meth:`_segment`); a frame that fails it,
        a payload longer than 8 bytes, and runs shorter than ``min_run`` go through
        :meth:`_validate`.
        """
        n = hi - lo
        if n <= 0:
            return
        if n < self.min_batch:
            self._scalar_rows(fa, lo, hi)
            return
        self._frames += n
        ft = fa.frame_type[lo:hi]
        data64 = np.ascontiguousarray(fa.data).view(np.uint64).reshape(-1)
        if ft.any():
            self._rejected["frame_type"] += int(np.count_nonzero(ft))
            nf = np.flatnonzero(~ft) + lo
            m = int(nf.size)
            if not m:
                return
            ts = fa.timestamp[nf]
            fid = fa.arbitration_id[nf]
            ext = fa.is_extended[nf]
            length = fa.length[nf]
            rows = data64[nf]
        else:
            nf = None
            m = n
            ts = fa.timestamp[lo:hi]
            fid = fa.arbitration_id[lo:hi]
            ext = fa.is_extended[lo:hi]
            length = fa.length[lo:hi]
            rows = data64[lo:hi]
        # ---- stateless checks: outcome per frame (see _OUTCOMES), route, payload
        keys = fid | (ext.astype(np.int64) << 31) if ext.any() else fid
        rkeys = self._rkeys   # never empty: a listener has at least one data message
        p = np.searchsorted(rkeys, keys)
        p[p >= rkeys.size] = 0
        hit = rkeys[p] == keys
        r = self._rnum[p]
        outcome = np.zeros(m, dtype=np.int8)
        if not hit.all():
            miss = ~hit
            known = np.isin(keys, self._ikeys) if self._ikeys.size else np.zeros(m, bool)
            outcome[miss] = np.where(known[miss], _O_IGNORED, _O_UNKNOWN)
            r = np.where(hit, r, -1)
        rdlc = self._rdlc[r]
        bad = hit & (length != rdlc)
        if bad.any():
            outcome[bad] = _O_DLC
        e2e = self._re2e[r] & (outcome == 0)
        if e2e.any():
            b8 = rows.view(np.uint8).reshape(m, 8)
            crc = self._rstart[r]
            lmin = int(rdlc[e2e].min())
            for i in range(1, int(rdlc[e2e].max())):
                nxt = _CRC_TABLE.take(crc ^ b8[:, i])
                crc = nxt if i < lmin else np.where(rdlc > i, nxt, crc)
            bad = e2e & ((crc ^ np.uint8(0xFF)) != b8[:, 0])
            if bad.any():
                outcome[bad] = _O_CRC
        # ---- the time check, segment by segment
        prev = np.empty(m)
        prev[0] = self._last_ts
        prev[1:] = ts[:-1]
        badt = ~((prev <= ts) & (ts < _INF))
        long_rows = None
        if fa.long_data:
            long_rows = length > 8
            badt |= long_rows
        bad_at = np.flatnonzero(badt).tolist()
        nb = len(bad_at)
        b = 0
        pos = 0
        while pos < m:
            # the frame at pos against the time base as it is now (an earlier frame may
            # have been rejected), the later ones against their predecessor
            while b < nb and bad_at[b] <= pos:
                b += 1
            if not self._last_ts <= float(ts[pos]) < _INF or (long_rows is not None
                                                              and long_rows[pos]):
                j = pos
            else:
                j = bad_at[b] if b < nb else m
            if j - pos >= max(1, self.min_run):
                self._segment(pos, j, ts, r, outcome, rows)
                pos = j
            else:
                end = min(j + 1, m)
                for k in range(pos, end):
                    i = int(nf[k]) if nf is not None else lo + k
                    self._validate(float(ts[k]), _row_key(fa, i), fa.payload(i))
                pos = end

    def _scalar_rows(self, fa: FrameArrays, lo: int, hi: int) -> None:
        """Frames ``lo:hi`` of ``fa`` one by one through the frame-by-frame path (counted,
        frame type checked, then :meth:`_validate`), the fields read as lists first.

        The small batches a window driver feeds between two checks go this way; the
        per-frame reads of NumPy scalars (~1 µs a frame) become list and bytes indexing.
        """
        ts = fa.timestamp[lo:hi].tolist()
        ids = fa.arbitration_id[lo:hi].tolist()
        ext = fa.is_extended[lo:hi].tolist()
        ft = fa.frame_type[lo:hi].tolist()
        lens = fa.length[lo:hi].tolist()
        raw = np.ascontiguousarray(fa.data[lo:hi]).tobytes()
        long_data = fa.long_data
        rejected = self._rejected
        validate = self._validate
        for k in range(hi - lo):
            self._frames += 1
            if ft[k]:
                rejected["frame_type"] += 1
                continue
            payload = long_data.get(lo + k) if long_data else None
            if payload is None:   # FrameArrays.payload: data[i, :length] (8 bytes at most)
                payload = raw[8 * k:8 * k + 8][:lens[k]]
            fid = ids[k]
            validate(ts[k], fid | _EXT if ext[k] else fid, payload)

    def _segment(self, lo: int, hi: int, ts: np.ndarray, r: np.ndarray, outcome: np.ndarray,
                 rows: np.ndarray) -> None:
        """Batch frames ``lo:hi`` (in order, all passing the time check).

        The stateless outcomes are counted; the frames that passed them are grouped by
        message (a stable sort keeps their order) for the counter and period rules
        (:meth:`_runs`) -- in tick mode SN_Sync first, whose accepted frames give every
        other frame its tick and period -- and per message decoded and stored
        (:meth:`_accepted`).
        """
        self._last_ts = float(ts[hi - 1])
        self._time_rejects = 0
        oc = outcome[lo:hi]
        if oc.any():
            cnt = np.bincount(oc, minlength=5).tolist()
            rejected = self._rejected
            rejected["unknown_id"] += cnt[_O_UNKNOWN]
            self._counts.ignored += cnt[_O_IGNORED]
            rejected["dlc"] += cnt[_O_DLC]
            rejected["crc"] += cnt[_O_CRC]
            h = np.flatnonzero(oc == 0) + lo
            if not h.size:
                return
            r_h = r[h]
        else:
            h = None
            r_h = r[lo:hi]
        nroutes = len(self._route_list)
        if r_h.size > 1 and (r_h[1:] < r_h[:-1]).any():
            order = np.argsort(r_h.astype(np.uint8 if nroutes < 256 else np.uint16),
                               kind="stable")
            h = order + lo if h is None else h[order]
            r_h = r_h[order]
        elif h is None:
            h = np.arange(lo, hi)
        rows = rows[h]
        arr = ts[h]
        cnt_r = np.bincount(r_h, minlength=nroutes)
        ends = np.cumsum(cnt_r).tolist()
        runs = [(k, ends[k] - c, ends[k]) for k, c in enumerate(cnt_r.tolist()) if c]
        syncs = _SyncTrack(self._sync_tick, self._sync_n, self._period) if self._tick_time \
            else None
        tsd = arr
        if syncs is not None and self._route_list[runs[0][0]].kind == _SYNC:
            # tick mode: SN_Sync first (its data time is its own Tick x PeriodUs)
            k, a, b = runs[0]
            route = self._route_list[k]
            b8 = rows[a:b].view(np.uint8).reshape(b - a, 8)
            vals = self._sync_values(route, b8)
            tk, pus = vals
            t_s = arr[a:b]
            if route.check is not None:
                if isinstance(tk, np.ndarray):
                    t_s = np.where(pus > 0, (tk * pus).astype(np.float64) / 1e6, t_s)
                else:
                    t_s = np.array([int(t) * u / 1e6 if u > 0 else x
                                    for t, u, x in zip(tk, pus, t_s.tolist())], dtype=np.float64)
                acc = self._runs(runs[:1], rows, arr, t_s, a, syncs)
            else:
                acc = np.ones(b - a, dtype=bool)
            self._accepted(route, b8, t_s, acc, vals, syncs, h[a:b])
            runs = runs[1:]
            if not runs:
                return
        if syncs is not None:
            # every other message: the SN_Sync state each frame sees, and the data time of
            # the E2E data frames: the tick nearest the last SN_Sync's with their counter's
            # residue mod 15, times the period
            a0 = runs[0][1]
            sn, st, known, per = syncs.at(h[a0:])
            syncs.sn, syncs.known, syncs.per, syncs.lo = sn, known, per, a0
            conv = known & ~np.isnan(per) & self._rdata_e2e[r_h[a0:]]
            tsd = arr
            if conv.any():
                c = (rows[a0:] >> np.uint64(8) & np.uint64(0x0F)).astype(np.int64)
                d = (st - c) % COUNTER_MODULUS
                tk = st - d + np.where(d <= COUNTER_MODULUS // 2, 0, COUNTER_MODULUS)
                tsd = arr.copy()
                tsd[a0:] = np.where(conv, np.round(tk * per * 1e6) / 1e6, arr[a0:])
        e2e_runs = [x for x in runs if self._route_list[x[0]].check is not None]
        if e2e_runs:
            a0, b0 = e2e_runs[0][1], e2e_runs[-1][2]
            acc = self._runs(e2e_runs, rows, arr, tsd[a0:b0], a0, syncs)
            for k, a, b in e2e_runs:
                self._accepted(self._route_list[k], rows[a:b].view(np.uint8).reshape(b - a, 8),
                               tsd[a:b], acc[a - a0:b - a0], None, syncs, h[a:b])
        for k, a, b in runs:
            route = self._route_list[k]
            if route.check is not None:
                continue
            # not E2E protected: no counter, the data time is the frame time
            if route.kind == _DATA and syncs is not None:
                self._rejected["no_sync"] += b - a
                continue
            b8 = rows[a:b].view(np.uint8).reshape(b - a, 8)
            sync_vals = self._sync_values(route, b8) if syncs is not None and \
                route.kind == _SYNC else None
            self._accepted(route, b8, arr[a:b], np.ones(b - a, dtype=bool), sync_vals, syncs,
                           h[a:b])

    def _runs(self, runs: list[tuple[int, int, int]], rows: np.ndarray, arr: np.ndarray,
              tsd: np.ndarray, lo: int, syncs: "_SyncTrack | None") -> np.ndarray:
        """Counter and period rules of consecutive message runs ``rows[lo:hi]``; accepted mask.

        ``runs`` are ``(route index, start, end)`` in the sorted frame arrays (``rows``:
        payloads as uint64, ``arr``: frame times), contiguous from ``lo``; ``tsd`` the data
        times of ``lo:hi``. In every run the prefix in which
        each counter advances by exactly one, each interval is positive and too short for
        the silence rule, and (tick mode) no data frame can be ``no_sync`` needs only the
        period recurrence; from its first other frame on, the rules of :meth:`_validate`
        run frame by frame.
        """
        hi = runs[-1][2]
        m = hi - lo
        routes = self._route_list
        c = (rows[lo:hi] >> np.uint64(8) & np.uint64(0x0F)).astype(np.int64)
        starts = np.array([a - lo for _, a, _ in runs], dtype=np.int64)
        rid = np.repeat(np.arange(len(runs)), [b - a for _, a, b in runs])
        last_c = np.array([routes[r].last_c for r, _, _ in runs], dtype=np.int64)
        last_t = np.array([routes[r].last_ts for r, _, _ in runs])
        per0 = np.array([routes[r].period for r, _, _ in runs])
        prev_c = np.empty(m, dtype=np.int64)
        prev_c[1:] = c[:-1]
        prev_c[starts] = last_c
        prev_t = np.empty(m)
        prev_t[1:] = tsd[:-1]
        prev_t[starts] = last_t
        el = tsd - prev_t
        good = (c - prev_c) % COUNTER_MODULUS == 1
        fresh = starts[last_c < 0]          # first frame ever of its message
        e = el.copy()
        e[fresh] = _INF
        run_min = np.minimum.reduceat(e, starts)
        bound = np.minimum(run_min, np.where(per0 > 0, per0, _INF))
        good &= (e > 0) & (e <= _SILENCE_SAFE * bound[rid])
        good[fresh] = True
        is_data = np.array([routes[r].kind == _DATA for r, _, _ in runs])
        if syncs is not None and is_data.any():
            # tick mode: a data frame is accepted only with a known tick and period, and
            # none may qualify for the stale-tick rule (no SN_Sync since the message's last
            # frame and a silence longer than 7 periods)
            o = lo - syncs.lo
            sn = syncs.sn[o:o + m]
            per = syncs.per[o:o + m]
            known = syncs.known[o:o + m]
            prev_sn = np.empty(m, dtype=np.int64)
            prev_sn[1:] = sn[:-1]
            prev_sn[starts] = [routes[r].sync_n for r, _, _ in runs]
            prev_a = np.empty(m)
            prev_a[1:] = arr[lo:hi - 1]
            prev_a[starts] = [routes[r].last_arrival for r, _, _ in runs]
            ok = known & ~np.isnan(per) & ((sn != prev_sn) | (arr[lo:hi] - prev_a <= 7 * per))
            ok[fresh] = known[fresh] & ~np.isnan(per[fresh])
            good &= ok | ~is_data[rid]
        bad = np.flatnonzero(~good).tolist()
        acc = np.ones(m, dtype=bool)
        # the fast prefix of every run: [s0 + skip, fb) of el feeds the period estimate
        fast: list[tuple[int, int, int, int]] = []
        for r, a, b in runs:
            s0, s1 = a - lo, b - lo
            fb = s1
            if bad:
                k = bisect_left(bad, s0)
                if k < len(bad) and bad[k] < s1:
                    fb = bad[k]
            fast.append((r, s0, s1, fb))
        periods = _ema([(routes[r].period, s0 + (1 if routes[r].last_c < 0 else 0), fb)
                        for r, s0, _, fb in fast], el)
        for (r, s0, s1, fb), p in zip(fast, periods):
            route = routes[r]
            n_fast = fb - s0
            if n_fast:
                route.period = p
                route.last_c = int(c[fb - 1])
                route.last_ts = float(tsd[fb - 1])
                if syncs is not None:   # tick mode
                    route.last_arrival = float(arr[lo + fb - 1])
                    route.sync_n = syncs.n0 + n_fast - 1 if route.kind == _SYNC else \
                        int(syncs.sn[lo + fb - 1 - syncs.lo])
            if fb < s1:
                acc[fb:s1] = self._route_rest(route, c[fb:s1].tolist(), tsd[fb:s1].tolist(),
                                              arr[lo + fb:lo + s1].tolist(), n_fast,
                                              lo + fb, syncs)
        return acc

    def _route_rest(self, route: _Route, cl: list[int], tl: list[float], al: list[float],
                    n_before: int, at: int, syncs: "_SyncTrack | None") -> np.ndarray:
        """The rules of :meth:`_validate` for frames of one message, one by one; accepted mask.

        ``cl``, ``tl``, ``al``: counters, data times, arrival times; ``n_before``: frames of
        this message accepted earlier in the segment; ``at``: position of the first frame
        in the sorted segment arrays (tick mode: index into the SN_Sync state).
        """
        rejected = self._rejected
        tick = syncs is not None
        is_data = route.kind == _DATA
        is_sync = route.kind == _SYNC
        n = len(cl)
        acc = np.zeros(n, dtype=bool)
        if syncs is not None:   # tick mode
            o = at - syncs.lo
            if is_sync:
                sn_sync = syncs.n0 + n_before
            else:
                snl = syncs.sn[o:o + n].tolist()
                perl = syncs.per[o:o + n].tolist()
                knownl = syncs.known[o:o + n].tolist()
        for k in range(n):
            ck = cl[k]
            t = tl[k]
            last = route.last_c
            if tick:
                sn = sn_sync if is_sync else snl[k]
                if is_data and knownl[k] and perl[k] == perl[k]:   # tick and period known
                    if (route.sync_n == sn and last >= 0 and al[k] - route.last_arrival
                            > COUNTER_MODULUS // 2 * max(route.period, perl[k])):
                        rejected["no_sync"] += 1
                        continue
                route.last_arrival = al[k]
                route.sync_n = sn
            if not self._step_counter(route, ck, t):
                continue
            if tick and is_data and not knownl[k]:
                rejected["no_sync"] += 1
                continue
            acc[k] = True
            if tick and is_sync:
                sn_sync += 1
        return acc

    def _sync_values(self, route: _Route, rows: np.ndarray) -> tuple[Any, Any]:
        """``(Tick, PeriodUs)`` of SN_Sync payloads: int64 arrays, or lists of decoded values."""
        if route.vsync is not None:
            return route.vsync(rows)
        vals = [route.decode(r.tobytes()) for r in rows[:, :route.dlc]]
        return [v[0] for v in vals], [v[1] for v in vals]

    def _accepted(self, route: _Route, rows: np.ndarray, tsd: np.ndarray,
                  acc: np.ndarray, sync_vals: tuple[Any, Any] | None,
                  syncs: "_SyncTrack | None", q: np.ndarray) -> None:
        """Decode and store (data) or apply (SN_Sync, SN_Status, alert) the accepted frames.

        ``rows`` (m, 8) uint8 payloads, ``tsd`` data times, ``acc`` accepted mask,
        ``sync_vals`` (tick mode SN_Sync) Tick and PeriodUs, ``q`` segment positions.
        """
        n_acc = int(np.count_nonzero(acc))
        if not n_acc:
            return
        kind = route.kind
        if kind == _DATA:
            if route.source is None or route.row is None:   # every _DATA route has both
                raise RuntimeError(f"data route {route.name} without a source or decoder")
            if n_acc < acc.size:
                rows = rows.view(np.uint64).reshape(-1)[acc].view(np.uint8).reshape(n_acc, 8)
                tsd = tsd[acc]
            if route.vrow is not None:
                vals = route.vrow(rows)
            else:
                L = route.dlc
                vals = np.array([route.row(r.tobytes()) for r in rows[:, :L]],
                                dtype=np.float64).reshape(n_acc, -1)
            route.source.push_many(tsd, vals)
        elif kind == _SYNC:
            at = np.flatnonzero(acc)
            if sync_vals is None:   # timestamp mode: only the last frames matter
                tick, _ = route.decode(rows[at[-1], :route.dlc].tobytes())
                self._sync_tick = int(tick)
                for i in at[::-1].tolist():
                    _, period_us = route.decode(rows[i, :route.dlc].tobytes())
                    if period_us > 0:
                        self._period = period_us * 1e-6
                        break
            else:
                if syncs is None:   # sync_vals are computed in tick mode only
                    raise RuntimeError("SN_Sync values without the tick-mode sync state")
                tk, pus = sync_vals
                if isinstance(tk, np.ndarray):
                    tk_acc, pus_acc = tk[at], pus[at]
                else:
                    tk_acc = np.array([int(tk[i]) for i in at.tolist()], dtype=np.int64)
                    pus_acc = np.array([pus[i] for i in at.tolist()], dtype=np.float64)
                syncs.add(q[at], tk_acc, pus_acc)
                self._sync_tick = int(tk_acc[-1])
                pos = np.flatnonzero(pus_acc > 0)
                if pos.size:
                    self._period = pus_acc[pos[-1]].item() * 1e-6
            self._sync_n += n_acc
        elif kind == _STATUS:
            i = int(np.flatnonzero(acc)[-1])
            state, rate, flags, busoff, sset = route.decode(rows[i, :route.dlc].tobytes())
            self._node_status = {"t": float(tsd[i]), "state": int(state),
                                 "sample_rate": float(rate), "fault_flags": int(flags),
                                 "busoff_count": int(busoff), "sensor_set": int(sset)}
        else:
            for i in np.flatnonzero(acc).tolist():
                if not self._special(route, rows[i, :route.dlc].tobytes(), float(tsd[i])):
                    n_acc -= 1
        route.accepted += n_acc
        self._counts.accepted += n_acc

    # ---- malformed input -------------------------------------------------------------------
    def count_malformed(self, n: int) -> None:
        """Count ``n`` log lines/records that could not be parsed into frames."""
        with self._lock:
            self._counts.rejected["malformed"] += n

    def on_error(self, exc: Exception) -> None:  # called by can.Notifier
        """Bus errors are counted as malformed input, never raised into the Notifier."""
        with self._lock:
            self._counts.rejected["malformed"] += 1

    def stop(self) -> None:
        """Process the queued frames (part of the can.Listener interface)."""
        self.flush()

    # ---- results (each read processes the queue first) -----------------------------------------
    @property
    def counts(self) -> FrameCounts:
        """Frame counters (accepted, ignored, lost, rejected by reason)."""
        self.flush()
        return self._counts

    @property
    def buffer(self) -> RollingBuffer:
        """The rolling buffer of decoded channels (its reads process the queue first)."""
        self.flush()
        return self._buffer

    @property
    def node_status(self) -> dict[str, object]:
        """Last ``SN_Status``: t, state, sample_rate, fault_flags, busoff_count, sensor_set."""
        self.flush()
        return self._node_status

    @property
    def alerts(self) -> list[dict[str, object]]:
        """``SUSPID_Alert`` frames accepted (model, parameter, value, nominal, severity, t)."""
        self.flush()
        return self._alerts

    @property
    def period(self) -> float | None:
        """Sample period (s) announced by the last ``SN_Sync`` with a period, or None."""
        self.flush()
        return self._period

    @property
    def frames(self) -> int:
        """Frames received (queued ones included)."""
        return self._frames + len(self._pending)

    @property
    def time_resyncs(self) -> int:
        """Times the time base was re-anchored after a clock reset."""
        self.flush()
        return self._time_resyncs

    def frame_stats(self) -> dict[str, object]:
        """``{"accepted": N, "rejected": {reason: n}, "ignored": n, "lost": n}`` (JSON-ready)."""
        c = self.counts
        out: dict[str, object] = {"accepted": c.accepted, "rejected": dict(c.rejected),
                                  "ignored": c.ignored, "lost": c.lost,
                                  "time_base": "tick" if self._tick_time else "timestamp"}
        if self.receive_stats:
            out["receive"] = dict(self.receive_stats)
        return out

    def per_message(self) -> dict[str, int]:
        """Accepted frames per DBC message name."""
        self.flush()
        return {r.name: r.accepted for r in self._routes.values()}

    def state(self) -> dict[str, object]:
        """Everything the validation carries from frame to frame (for comparisons and tests).

        Returns
        -------
        dict
            Time base (last time, pending rejections, re-anchorings), SN_Sync tick, count
            and period, and per message the counter, last data time, period estimate,
            arrival time and SN_Sync count of its last frame.
        """
        self.flush()
        return {"last_ts": self._last_ts, "time_rejects": self._time_rejects,
                "time_resyncs": self._time_resyncs, "sync_tick": self._sync_tick,
                "sync_n": self._sync_n, "period": self._period, "frames": self._frames,
                "routes": {r.name: (r.last_c, r.last_ts, r.period, r.accepted, r.last_arrival,
                                    r.sync_n) for r in self._routes.values()}}

    @property
    def channels(self) -> list[str]:
        """Mapped channels (order of the map)."""
        return self.signal_map.channels()

    def aligned(self, window: float | None = None, t_end: float | None = None,
                dt: float | None = None, channels: Sequence[str] | None = None) -> Aligned:
        """Buffered channels on a uniform grid (NaN and gap records where samples are missing).

        Parameters
        ----------
        window : float, optional
            Length (s) of the window ending at ``t_end`` (default: everything buffered).
        t_end : float, optional
            End of the window (s, data time); default the newest sample.
        dt : float, optional
            Grid step (s); default the ``SN_Sync`` period in tick mode, else the median
            frame interval.
        channels : sequence of str, optional
            Default every mapped channel.

        Returns
        -------
        Aligned
            Channels whose map subtracts the mean have the mean of the window removed.
        """
        self.flush()
        if dt is None and self.time_source == "tick":
            dt = self._period
        t_start = None
        buf = self._buffer
        if window is not None:
            end = buf.latest_time() if t_end is None else t_end
            t_start = end - window
            t_end = end
        al = buf.align(channels if channels is not None else self.channels, dt, t_start, t_end)
        for ch in self.mean_channels:
            if ch in al.values:
                v = al.values[ch]
                if (~np.isnan(v)).any():
                    al.values[ch] = v - float(np.nanmean(v))
        return al


def _ema(jobs: list[tuple[float, int, int]], el: np.ndarray) -> list[float]:
    """Period estimates after the recurrence over ``el[start:stop]`` for every job.

    ``jobs``: ``(period before, start, stop)``; the recurrence is the scalar code's
    ``period = el if period <= 0 else 0.9 * period + 0.1 * el``. A Python loop: the result
    must be bit for bit the scalar one, and no array operation rounds the same way step by
    step (``scipy.signal.lfilter`` would, but importing ``scipy.signal`` costs ~1 s per
    process start).

    The loop is the scalar one with two steps taken out of it, which changes no rounding:
    the products ``0.1 * el`` are computed as one array operation (one IEEE multiplication
    each, the same double), and the test ``period > 0`` is made once: when every product
    is positive, a positive period stays positive (``0.9 * p`` is >= 0 and adding a
    positive double to it rounds to at least that double), so the test would always pass.
    A job with a non-positive (or NaN) product runs the scalar loop as it is.
    """
    out = []
    for p, a, b in jobs:
        if a >= b:
            out.append(p)
            continue
        xs = el[a:b]
        if not p > 0:            # no estimate yet (or NaN): the first interval becomes it
            p = float(xs[0])
            xs = xs[1:]
        ys = 0.1 * xs
        if p > 0 and bool((ys > 0).all()):
            for y in ys.tolist():
                p = 0.9 * p + y
        else:
            for x in xs.tolist():
                p = 0.9 * p + 0.1 * x if p > 0 else x
        out.append(p)
    return out


def _row_key(fa: FrameArrays, i: int) -> int:
    """Route key (CAN ID | extended flag) of frame ``i``."""
    fid = int(fa.arbitration_id[i])
    return fid | _EXT if fa.is_extended[i] else fid


def _compile_sync(codec: MessageCodec) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None:
    """``rows -> (Tick, PeriodUs)`` int64 arrays when both decode to plain integers."""
    specs = codec.specs
    if any(s.is_float or s.scale != 1.0 or s.offset != 0.0 for s in specs):
        return None
    f_tick, f_per = (compile_raw(s, codec.length) for s in specs)
    if f_tick is None or f_per is None or any(s.length > 31 + 1 for s in specs):
        return None

    def values(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return f_tick(rows), f_per(rows)

    return values


class _SyncTrack:
    """SN_Sync state along a segment (tick mode): what every frame position sees.

    Parameters
    ----------
    tick0 : int or None
        ``Tick`` of the last accepted SN_Sync before the segment.
    n0 : int
        SN_Sync frames accepted before the segment.
    period0 : float or None
        Period (s) before the segment.
    """

    def __init__(self, tick0: int | None, n0: int, period0: float | None) -> None:
        self.tick0 = tick0
        self.n0 = n0
        self.period0 = period0
        self.pos = np.empty(0, dtype=np.int64)
        self.ticks = np.empty(0, dtype=np.int64)
        self.periods = np.empty(0)
        # filled by the segment for the frames of the other messages (from index lo of the
        # sorted segment arrays on): SN_Sync count, tick known, period (NaN unknown)
        self.lo = 0
        self.sn = np.empty(0, dtype=np.int64)
        self.known = np.empty(0, dtype=bool)
        self.per = np.empty(0)

    def add(self, pos: np.ndarray, ticks: np.ndarray, period_us: np.ndarray) -> None:
        """The accepted SN_Sync frames of the segment: positions, ticks, periods (µs)."""
        given = period_us > 0
        last = np.maximum.accumulate(np.where(given, np.arange(given.size), -1))
        per = (period_us * 1e-6) if period_us.dtype.kind == "f" else \
            period_us.astype(np.float64) * 1e-6
        self.pos = np.asarray(pos, dtype=np.int64)
        self.ticks = np.asarray(ticks, dtype=np.int64)
        self.periods = np.where(last >= 0, per[np.maximum(last, 0)],
                                math.nan if self.period0 is None else self.period0)

    def at(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """At segment positions ``q``: SN_Sync count, tick, tick known, period (NaN unknown)."""
        k = np.searchsorted(self.pos, q)
        sn = self.n0 + k
        has = k > 0
        km1 = np.maximum(k - 1, 0)
        if self.ticks.size:
            st = np.where(has, self.ticks[km1], 0 if self.tick0 is None else self.tick0)
            per = np.where(has, self.periods[km1],
                           math.nan if self.period0 is None else self.period0)
        else:
            st = np.full(q.size, 0 if self.tick0 is None else self.tick0, dtype=np.int64)
            per = np.full(q.size, math.nan if self.period0 is None else self.period0)
        known = has | (self.tick0 is not None)
        return sn, st.astype(np.int64), known, per
