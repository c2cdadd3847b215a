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
With the timestamps and ``arrival_slots=True``, a whole log fed through
:func:`~estimator.decode.replay.feed_log` has its data frames placed in their sample slots
from their arrival times first (:mod:`estimator.decode.rules.arrival`); frames handed over
one by one (:meth:`DecodeListener.on_message_received`, a live bus) go through the causal
version of that rule (:mod:`estimator.decode.rules.arrival_live`), which holds the last few
frames of each message until :meth:`DecodeListener.finish`. The frame statistics then list
per message what was placed (``arrival_slots``).

Feed it like any python-can listener: ``can.Notifier(bus, [listener])`` on a live bus, or
:func:`estimator.decode.replay.feed_log` for a log (no reader thread and queue hand-off, so
replay runs at decode speed and is deterministic; :class:`estimator.decode.replay.ReplayBus`
runs the same log through a Notifier).

Parts
-----
This module is the python-can side only: :class:`DecodeListener` queues the messages a
``can.Notifier`` (or :func:`~estimator.decode.replay.feed`) hands it and passes them in
batches to :class:`~estimator.decode.engine.DecodeEngine`, which validates, decodes and
stores them (the rules it applies are the modules of :mod:`estimator.decode.rules`: E2E,
counters, time base). A log replay (:func:`~estimator.decode.replay.feed_log`) hands the
engine arrays through :meth:`DecodeListener.feed_arrays`; the queued live frames become
the same arrays (:meth:`~suspid.can.logs.FrameArrays.from_messages`) and take the same
entry, :meth:`~estimator.decode.engine.DecodeEngine.process`: a live bus and a log share
one decode path.

``on_message_received`` only queues the message (a few hundred ns); the queue is processed
when ``batch_size`` frames are waiting, when a ``SUSPID_Alert`` frame arrives (with
``on_alert``, so it is called at once), and before anything reads the listener's results
-- ``counts``, ``frame_stats()``, ``aligned()``, ``buffer``, ``node_status``, ``alerts``,
``period``... -- so a reader always sees every frame received so far and callers need not
know about the queue (:meth:`DecodeListener.flush` does it explicitly). ``batch_size=1``
processes every frame on arrival as a batch of one (same results whatever the batch size,
property-tested in ``tests/can/test_batch_equivalence.py``).
"""
from __future__ import annotations

import copy
import threading
from collections import deque
from pathlib import Path
from typing import Any, Callable, Literal, Sequence

import can
import numpy as np
from cantools.database.can import Database

from estimator.decode.buffer import Aligned, RollingBuffer
from estimator.decode.engine import MIN_RUN, SMALL_BATCH, DecodeEngine
from estimator.decode.frames import sort_frames
from estimator.decode.j1939 import J1939Match
from estimator.decode.routes import DATA, EXT, SYNC, Routes, compile_row, model_channels
from estimator.decode.rules.arrival import arrival_slots, place_messages
from estimator.decode.rules.arrival_live import LivePlacer, retimed
from estimator.decode.rules.counters import period_after
from estimator.decode.rules.timebase import AUTO_FRAMES, TIME_RESYNC, choose_time_base, first_sync
from estimator.decode.stats import REJECT_REASONS, FrameCounts
from suspid.can.crc import COUNTER_MODULUS
from suspid.can.dbc import SYNC_MESSAGE, load_dbc
from suspid.can.logs import FrameArrays
from suspid.can.signal_map import SignalMap, SignalMapLike, as_signal_map
from suspid.errors import UsageError
from suspid.io.csvio import AUX_CHANNELS
from suspid.models import SuspensionModel, get_model

#: frames waiting before ``on_message_received`` processes the queue (default batch size)
BATCH_SIZE = 2048
#: earlier names of what now lives in the decoder's parts
_ema = period_after
_compile_row = compile_row

__all__ = ["AUTO_FRAMES", "BATCH_SIZE", "DecodeListener", "FrameCounts", "MIN_RUN",
           "REJECT_REASONS", "SMALL_BATCH", "TIME_RESYNC", "model_channels"]


def _key_of(msg: can.Message) -> int | None:
    """Route key of a frame (None: error and remote frames, which carry no data)."""
    if msg.is_error_frame or msg.is_remote_frame:
        return None
    return msg.arbitration_id | EXT if msg.is_extended_id else msg.arbitration_id


def _as_arrays(msgs: list[can.Message], counts: FrameCounts) -> FrameArrays:
    """The queued messages as one batch of :class:`~suspid.can.logs.FrameArrays`.

    A message whose fields python-can does not check (a bus or a caller may set
    ``timestamp=None`` or a payload that is not bytes-like) cannot be converted: it is
    counted as ``malformed`` and left out of the batch.
    """
    try:
        return FrameArrays.from_messages(msgs)
    except (TypeError, ValueError, OverflowError):
        pass
    good = []
    for m in msgs:
        try:
            FrameArrays.from_messages([m])
        except (TypeError, ValueError, OverflowError):
            counts.rejected["malformed"] += 1
            continue
        good.append(m)
    return FrameArrays.from_messages(good)


def _time_of(msg: can.Message) -> float:
    """Arrival time (s) of a frame (NaN when it has none the rule can use)."""
    try:
        return float(msg.timestamp)
    except (TypeError, ValueError):
        return float("nan")


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
        batch (any read of the results processes the queue first). ``1`` processes every
        frame on arrival (same results).
    on_alert : callable, optional
        Called with each accepted ``SUSPID_Alert`` (the dict appended to ``alerts``), in
        order, as soon as the frame is received (an alert frame flushes the queue).
    arrival_slots : bool
        A whole log fed with the timestamp time base
        (:func:`~estimator.decode.replay.feed_log`) has its data frames placed in their
        sample slots from their arrival times first (:meth:`place_arrivals`), so arrival
        jitter, bursts and delivery delay lose no frame and move no sample; frames fed one
        by one (:meth:`on_message_received`) are placed as they arrive
        (:mod:`estimator.decode.rules.arrival_live`; :meth:`finish` releases the last).
    j1939_source : str or int, optional
        A DBC with J1939 messages: extended frames are matched to them by PGN
        (:class:`~estimator.decode.j1939.J1939Match`), from this source address only
        (``"0x47"``); default the first sender of each PGN.

    Attributes
    ----------
    engine : DecodeEngine
        Validation, decoding and the state carried from frame to frame.
    time_source : str
        The time base in use (``"tick"`` or ``"timestamp"``; ``"timestamp"`` while
        ``"auto"`` is undecided).
    time_source_requested : str
    mean_channels : list of str
        Channels whose map subtracts the data's mean (applied at alignment).
    receive_stats : dict
        Live reception's own counters (frames read, lost by cause), set by the receiver.
    """

    def __init__(self, model: str | SuspensionModel, dbc: str | Path | Database | None = None,
                 signal_map: SignalMapLike = None, *, capacity: int = 1 << 16,
                 growable: bool = False,
                 time_source: Literal["timestamp", "tick", "auto"] = "timestamp",
                 max_counter_delta: int = 4, stale_window: int = 5,
                 batch_size: int = BATCH_SIZE,
                 on_alert: Callable[[dict[str, object]], None] | None = None,
                 arrival_slots: bool = False, j1939_source: str | int | None = None) -> None:
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
        # the motions and roads, the ride heights (strut extensions) measured like them, and
        # the vehicle's speed and odometer (never fitted: the fleet's distance per drive)
        smap.validate(db, model_channels(self.model) + list(self.model.ride_height_channels)
                      + list(AUX_CHANNELS))
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
        if batch_size < 1:
            raise UsageError(f"batch_size must be >= 1, got {batch_size}")
        self.max_counter_delta = max_counter_delta
        self.stale_window = max(0, min(stale_window, COUNTER_MODULUS - 1 - max_counter_delta))
        self._buffer = RollingBuffer(capacity, growable)
        self.mean_channels = [m.channel for m in smap.mappings if m.remove_mean]
        self.receive_stats: dict[str, object] = {}
        self.arrival_slots = arrival_slots
        #: what :meth:`place_arrivals` did, per message (empty: not used)
        self.arrival_stats: dict[str, dict[str, object]] = {}
        self._slot_period = 0.0
        self._live: LivePlacer | None = None
        self._live_off = False
        routes = Routes(db, smap, self._buffer)
        #: J1939 frames matched by PGN (:mod:`estimator.decode.j1939`); None: no J1939 DBC
        self.j1939 = J1939Match.from_db(db, j1939_source)
        if time_source == "tick" and not any(r.kind == SYNC for r in routes.ordered):
            raise UsageError(f"time_source 'tick' needs message {SYNC_MESSAGE} in the DBC "
                             f"{getattr(self.db, 'suspid_path', '')}")
        self.routes = routes
        self.engine = DecodeEngine(db, routes, self._buffer, tick_time=time_source == "tick",
                                   max_counter_delta=max_counter_delta,
                                   stale_window=self.stale_window,
                                   collect_alerts=on_alert is not None)
        self.batch_size = batch_size
        self.on_alert = on_alert
        self._lock = threading.RLock()         # one batch (or frame) processed at a time
        self._pending: deque[can.Message] = deque()
        # an alert frame is processed at once when someone waits for alerts
        self._prompt = routes.alert_ids if on_alert is not None else frozenset()
        if not routes.sync_ids.size:
            self._auto = False   # no SN_Sync in the DBC: the timestamps are the only clock

    # ---- tuning of the batch path (same results) ----------------------------------------
    @property
    def min_batch(self) -> int:
        """Batches smaller than this are validated frame by frame."""
        return self.engine.min_batch

    @min_batch.setter
    def min_batch(self, value: int) -> None:
        self.engine.min_batch = value

    @property
    def min_run(self) -> int:
        """Runs of frames between time anomalies shorter than this go frame by frame."""
        return self.engine.min_run

    @min_run.setter
    def min_run(self, value: int) -> None:
        self.engine.min_run = value

    # ---- reception -------------------------------------------------------------------
    def on_message_received(self, msg: can.Message) -> None:
        """Queue one frame; the queue is validated, decoded and buffered as one batch.

        The frame's fields are read when the batch is processed (at the latest when anything
        reads the results), as python-can's ``BufferedReader`` keeps messages: do not modify
        a message after handing it over. With ``batch_size=1`` the frame is processed now.
        With ``arrival_slots`` and the timestamp time base the frame goes through the live
        slot rule first (:mod:`estimator.decode.rules.arrival_live`), which holds the last
        few frames of each data message (its look-ahead) and passes frames on in time order
        with their slot times (:meth:`finish` releases the held ones).
        """
        if self.j1939 is not None:
            got = self.j1939.message(msg)
            if got is None:
                return
            msg = got
        if self._auto:
            # frames queued before the time base is decided keep their arrival times; later
            # ones placed in slots could fall before them: the stream stays unplaced
            self._live_off = True
        elif self.arrival_slots and not self._live_off and not self.engine.tick_time:
            live = self._live
            if live is None:
                live = self._live = self._placer()
            for m in live.push(msg):
                self._receive(m)
            return
        self._receive(msg)

    def _placer(self) -> LivePlacer:
        """The live slot rule over this listener's data messages."""
        names = {r.key: r.name for r in self.routes.ordered if r.kind == DATA}
        return LivePlacer(names, _key_of, _time_of, retimed)

    def _receive(self, msg: can.Message) -> None:
        """Queue one frame; process the queue once it holds ``batch_size`` frames (or the
        frame is an alert someone waits for)."""
        pend = self._pending
        pend.append(msg)
        if len(pend) >= self.batch_size or msg.arbitration_id in self._prompt:
            self.flush()

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
        arr = np.asarray(ids, dtype=np.int64) & ~EXT
        base = choose_time_base(arr, self.routes.sync_ids, self.routes.known_ids, final)
        if base is None:
            return False   # foreign traffic does not count: only frames of the DBC decide
        if base == "tick":
            self.time_source = "tick"
            self.engine.tick_time = True
        self._auto = False
        return True

    def sync_first_index(self, ids: Any) -> int:
        """Tick base, start of a stream: where the first ``SN_Sync`` frame lies among the
        first frames ``ids`` (-1: none, or not the start of a stream).

        Frames of the first sample that arrived before its ``SN_Sync`` (arrival jitter) have
        no tick yet; the callers move that SN_Sync to the front, with the first frame's
        arrival time, so they are placed in their sample instead of rejected (``no_sync``).
        """
        eng = self.engine
        c = eng.counts
        if not eng.tick_time or eng.sync_tick is not None or \
                c.accepted + c.ignored + sum(c.rejected.values()) > 0:
            return -1
        return first_sync(np.asarray(ids, dtype=np.int64)[:AUTO_FRAMES] & ~EXT,
                          self.routes.sync_ids)

    def finish(self) -> None:
        """The input has ended: process every held frame (see ``time_source="auto"``; the
        live slot rule's look-ahead)."""
        live = self._live
        if live is not None:
            for m in live.finish():
                self._receive(m)
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
                self.engine.process(_as_arrays(msgs, self.engine.counts), 0, n)
        if self.engine.outbox:
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
        taken = stop - start
        if self.j1939 is not None:
            rows = np.zeros(len(frames), dtype=bool)
            rows[start:stop] = True
            frames = self.j1939.arrays(frames.select(rows) if taken < len(frames) else frames)
            start, stop = 0, len(frames)
            if not stop:
                return taken
        if self._auto:
            with self._lock:
                self.choose_time_base(
                    np.concatenate([np.array([m.arbitration_id for m in self._pending], np.int64),
                                    np.asarray(frames.arbitration_id[start:stop], np.int64)]),
                    final=True)
        self.flush()
        with self._lock:
            self.engine.process(frames, start, stop)
        if self.engine.outbox:
            self._deliver()
        return taken

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

    def places_arrivals(self) -> bool:
        """Whether a whole log fed now is placed in sample slots first (``arrival_slots``
        and the timestamp time base decided)."""
        return self.arrival_slots and not self._auto and not self.engine.tick_time

    def data_keys(self) -> list[int]:
        """Route keys (CAN ID | extended flag, bit 31) of the data messages."""
        return [r.key for r in self.routes.ordered if r.kind == DATA]

    def message_slot_times(self, arrivals: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
        """Data times of the data messages' frames placed in their sample slots
        (:mod:`estimator.decode.rules.arrival`).

        Parameters
        ----------
        arrivals : dict
            Route key (:meth:`data_keys`) -> arrival times (s) of the message's frames in a
            whole log (error and remote frames left out), in log order.

        Returns
        -------
        dict
            Route key -> data times (s) of the messages that are moved. Messages whose
            arrival times already lie on a uniform grid (or were stamped by a clock that
            ticks with the samples), or that cannot be placed (too few frames, times not
            finite or going back), keep their timestamps and are not listed. What was done
            is kept in :attr:`arrival_stats` and reported by :meth:`frame_stats`.
        """
        names, keys, slots = [], [], []
        for r in self.routes.ordered:
            t = arrivals.get(r.key)
            if r.kind != DATA or t is None or not t.size:
                continue
            sl = arrival_slots(t)
            if sl is not None:
                names.append(r.name)
                keys.append(r.key)
                slots.append(sl)
        out: dict[int, np.ndarray] = {}
        for name, key, sl, tm in zip(names, keys, slots, place_messages(slots)):
            if tm is not None:
                out[key] = tm
                self._slot_period = sl.period if not self._slot_period else \
                    min(self._slot_period, sl.period)
            self.arrival_stats[name] = {"period": sl.period, "missing": sl.missing,
                                        "retimed": tm is not None}
        return out

    def place_arrivals(self, frames: FrameArrays) -> FrameArrays:
        """``frames`` (a whole log, in log order) with the data frames' timestamps replaced
        by :meth:`message_slot_times`, sorted by time; ``frames`` itself when no frame
        moves or the timestamps are not all finite and in order (the time check handles
        those)."""
        ts = frames.timestamp
        if ts.size < 2 or not bool(np.isfinite(ts).all()) or bool((np.diff(ts) < 0).any()):
            return frames
        keys = frames.arbitration_id | (frames.is_extended.astype(np.int64) << 31)
        good = ~frames.frame_type
        where = {k: np.flatnonzero((keys == k) & good) for k in self.data_keys()}
        moved = self.message_slot_times({k: ts[i] for k, i in where.items()})
        if not moved:
            return frames
        out = ts.copy()
        for k, tm in moved.items():
            out[where[k]] = tm
        placed = copy.copy(frames)
        placed.timestamp = out
        return sort_frames(placed)

    def _live_stats(self) -> None:
        """Take what the live slot rule did into :attr:`arrival_stats`."""
        if self._live is None:
            return
        self.arrival_stats.update(self._live.stats())
        periods = [float(v["period"]) for v in self.arrival_stats.values()  # type: ignore[arg-type]
                   if v["retimed"]]
        if periods:
            self._slot_period = min(periods)

    def _deliver(self) -> None:
        """Hand accepted alerts to ``on_alert`` (outside the processing lock)."""
        with self._lock:
            out, self.engine.outbox = self.engine.outbox, []
        if self.on_alert is not None:
            for alert in out:
                self.on_alert(alert)

    # ---- malformed input -------------------------------------------------------------------
    def count_malformed(self, n: int) -> None:
        """Count ``n`` log lines/records that could not be parsed into frames."""
        with self._lock:
            self.engine.counts.rejected["malformed"] += n

    def on_error(self, exc: Exception) -> None:  # called by can.Notifier
        """Bus errors are counted as malformed input, never raised into the Notifier."""
        with self._lock:
            self.engine.counts.rejected["malformed"] += 1

    def stop(self) -> None:
        """Process the queued frames (part of the can.Listener interface)."""
        self.flush()

    # ---- results (each read processes the queue first) -----------------------------------------
    @property
    def counts(self) -> FrameCounts:
        """Frame counters (accepted, ignored, lost, rejected by reason)."""
        self.flush()
        return self.engine.counts

    @property
    def buffer(self) -> RollingBuffer:
        """The rolling buffer of decoded channels, with every frame received so far."""
        self.flush()
        return self._buffer

    @property
    def node_status(self) -> dict[str, object]:
        """Last ``SN_Status``: t, state, sample_rate, fault_flags, busoff_count, sensor_set."""
        self.flush()
        return self.engine.node_status

    @property
    def alerts(self) -> list[dict[str, object]]:
        """``SUSPID_Alert`` frames accepted (model, parameter, value, nominal, severity, t)."""
        self.flush()
        return self.engine.alerts

    @property
    def period(self) -> float | None:
        """Sample period (s) announced by the last ``SN_Sync`` with a period, or None."""
        self.flush()
        return self.engine.period

    @property
    def frames(self) -> int:
        """Frames received (queued ones included)."""
        return self.engine.frames + len(self._pending)

    @property
    def time_resyncs(self) -> int:
        """Times the time base was re-anchored after a clock reset."""
        self.flush()
        return self.engine.order.resyncs

    def frame_stats(self) -> dict[str, object]:
        """``{"accepted": N, "rejected": {reason: n}, "ignored": n, "lost": n,
        "time_base": "tick" | "timestamp"}`` (JSON-ready); ``arrival_slots`` (message ->
        ``period``, ``missing``, ``retimed``) when a log was placed in sample slots,
        ``receive`` when live; ``node_restarts`` and ``tick_wraps`` when the sensor clock
        restarted or wrapped (:class:`~estimator.decode.rules.timebase.TickClock`);
        ``unknown_page`` (message -> frames) when frames of a multiplexed message carried a
        multiplexer value that is no page of the DBC (:meth:`unknown_pages`)."""
        c = self.counts
        out: dict[str, object] = {"accepted": c.accepted, "rejected": dict(c.rejected),
                                  "ignored": c.ignored, "lost": c.lost,
                                  "time_base": "tick" if self.engine.tick_time else "timestamp"}
        clock = self.engine.clock
        if clock.restarts:
            out["node_restarts"] = clock.restarts
        if clock.wraps:
            out["tick_wraps"] = clock.wraps
        self._live_stats()
        if self.arrival_stats:
            out["arrival_slots"] = {k: dict(v) for k, v in self.arrival_stats.items()}
        if self.receive_stats:
            out["receive"] = dict(self.receive_stats)
        unknown = self.unknown_pages()
        if unknown:
            out["unknown_page"] = unknown
        if self.j1939 is not None:
            out["j1939"] = self.j1939.stats()
        return out

    def unknown_pages(self) -> dict[str, int]:
        """Per multiplexed data message, the accepted frames whose multiplexer value is no
        page of the DBC (:attr:`estimator.decode.pages.PageSplit.unknown`; stored in no
        page's ring); messages without such frames are left out."""
        self.flush()
        return {r.name: r.pages.unknown for r in self.routes.ordered
                if r.pages is not None and r.pages.unknown}

    def per_message(self) -> dict[str, int]:
        """Accepted frames per DBC message name."""
        self.flush()
        return {r.name: r.accepted for r in self.routes.by_key.values()}

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
        eng = self.engine
        return {"last_ts": eng.order.last, "time_rejects": eng.order.rejects,
                "time_resyncs": eng.order.resyncs, "sync_tick": eng.sync_tick,
                "sync_n": eng.sync_n, "period": eng.period, "frames": eng.frames,
                "routes": {r.name: (r.last_c, r.last_ts, r.period, r.accepted, r.last_arrival,
                                    r.sync_n) for r in self.routes.by_key.values()}}

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
        self._live_stats()
        if dt is None and self.time_source == "tick":
            dt = self.engine.period
        t_start = None
        buf = self._buffer
        if window is not None:
            end = buf.latest_time() if t_end is None else t_end
            t_start = end - window
            t_end = end
            if self._slot_period:
                # slot times a + k P: a sample on a window's edge is in it whatever the
                # last bits of the estimated P
                t_start -= 0.25 * self._slot_period
                t_end += 0.25 * self._slot_period
        al = buf.align(channels if channels is not None else self.channels, dt, t_start, t_end)
        for ch in self.mean_channels:
            if ch in al.values:
                v = al.values[ch]
                if (~np.isnan(v)).any():
                    al.values[ch] = v - float(np.nanmean(v))
        return al
