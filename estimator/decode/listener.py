"""The estimator's CAN front end: a python-can Listener that validates, decodes and buffers.

Every frame is checked in order (frame type, time order, known ID, DLC, E2E CRC, alive
counter, in tick mode a known tick); the first failing check names the rejection reason
(docs/can.md "Rejection classes"); a bad frame is counted and dropped, never fatal. Queued
frames go as arrays to :meth:`~estimator.decode.engine.DecodeEngine.process`, the one decode
path of a live bus and a log, at the latest before any result is read.
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
from estimator.decode.engine import DecodeEngine
from estimator.decode.j1939 import J1939Match
from estimator.decode.routes import DATA, EXT, SYNC, Routes, model_channels
from estimator.decode.rules.arrival import arrival_slots, place_messages
from estimator.decode.rules.arrival_live import LivePlacer
from estimator.decode.rules.counters import REJECT_REASONS, FrameCounts
from estimator.decode.rules.timebase import AUTO_FRAMES, choose_time_base, first_sync
from suspid.can.crc import COUNTER_MODULUS
from suspid.can.dbc import SYNC_MESSAGE, load_dbc
from suspid.can.logs import FrameArrays
from suspid.can.signal_map import SignalMap, SignalMapLike, as_signal_map
from suspid.errors import UsageError
from suspid.io.csvio import AUX_CHANNELS
from suspid.models import SuspensionModel, get_model

#: frames waiting before ``on_message_received`` processes the queue (default batch size)
BATCH_SIZE = 2048

__all__ = ["BATCH_SIZE", "DecodeListener", "REJECT_REASONS", "model_channels"]


def _as_arrays(msgs: list[can.Message], counts: FrameCounts) -> FrameArrays:
    """The queued messages as one batch; unconvertible ones counted ``malformed`` and left out."""
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


class DecodeListener(can.Listener):
    """Validate, decode and buffer the frames of a suspension sensor bus.

    ``dbc`` (default suspid's) and ``signal_map`` (``channel = MESSAGE.SIGNAL``; default the
    DBC's ``SuspidChannel`` attributes); ``capacity`` rows per message in the rolling buffer
    (``growable``: grow it instead of overwriting); ``time_source``: data time from the frame
    timestamps, the ``SN_Sync`` tick, or ``"auto"`` (the tick when an ``SN_Sync`` comes among
    the first ``AUTO_FRAMES`` frames of the DBC); ``max_counter_delta`` the largest accepted
    counter advance; ``batch_size`` frames queued before they are processed (``1``: on
    arrival); ``on_alert(alert)`` called for each accepted ``SUSPID_Alert`` as it arrives;
    ``arrival_slots``: with timestamps, place data frames in their sample slots;
    ``j1939_source``: a J1939 DBC's PGNs decoded from this source address only (``"0x47"``).
    :attr:`time_source` names the time base in use, :attr:`receive_stats` live counters.
    """

    def __init__(self, model: str | SuspensionModel, dbc: str | Path | Database | None = None,
                 signal_map: SignalMapLike = None, *, capacity: int = 1 << 16,
                 growable: bool = False,
                 time_source: Literal["timestamp", "tick", "auto"] = "timestamp",
                 max_counter_delta: int = 4, batch_size: int = BATCH_SIZE,
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
        # motions, roads, ride heights, and speed and odometer (never fitted)
        smap.validate(db, model_channels(self.model) + list(self.model.ride_height_channels)
                      + list(AUX_CHANNELS))
        self.signal_map = smap
        if time_source not in ("timestamp", "tick", "auto"):
            raise UsageError(f"time_source must be 'timestamp', 'tick' or 'auto', "
                             f"got {time_source!r}")
        self._auto = time_source == "auto"
        self.time_source_requested = time_source
        self.time_source = "timestamp" if self._auto else time_source
        if not 1 <= max_counter_delta <= COUNTER_MODULUS - 2:
            raise UsageError(f"max_counter_delta must be 1..13, got {max_counter_delta}")
        if batch_size < 1:
            raise UsageError(f"batch_size must be >= 1, got {batch_size}")
        self._buffer = RollingBuffer(capacity, growable)
        self.mean_channels = [m.channel for m in smap.mappings if m.remove_mean]
        self.receive_stats: dict[str, object] = {}
        self.arrival_slots = arrival_slots
        #: what the slot rule did, per message (empty: not used)
        self.arrival_stats: dict[str, dict[str, object]] = {}
        self._slot_period = 0.0
        self._live: LivePlacer | None = None
        self._live_off = False
        routes = Routes(db, smap, self._buffer)
        #: None: no J1939 DBC
        self.j1939 = J1939Match.from_db(db, j1939_source)
        if time_source == "tick" and not any(r.kind == SYNC for r in routes.ordered):
            raise UsageError(f"time_source 'tick' needs message {SYNC_MESSAGE} in the DBC "
                             f"{getattr(self.db, 'suspid_path', '')}")
        self.routes = routes
        self.engine = DecodeEngine(db, routes, tick_time=time_source == "tick",
                                   max_counter_delta=max_counter_delta,
                                   collect_alerts=on_alert is not None)
        self.batch_size = batch_size
        self.on_alert = on_alert
        self._lock = threading.RLock()         # one batch processed at a time
        self._pending: deque[can.Message] = deque()
        self._prompt = routes.alert_ids if on_alert is not None else frozenset()
        if not routes.sync_ids.size:
            self._auto = False   # no SN_Sync in the DBC: the timestamps are the only clock

    def on_message_received(self, msg: can.Message) -> None:
        """Queue one frame (not to be modified after), through the live slot rule with ``arrival_slots``."""
        if self.j1939 is not None:
            got = self.j1939.message(msg)
            if got is None:
                return
            msg = got
        if self._auto:
            # frames queued undecided keep their arrival times: the stream stays unplaced
            self._live_off = True
        elif self.arrival_slots and not self._live_off and not self.engine.tick_time:
            live = self._live
            if live is None:
                names = {r.key: r.name for r in self.routes.ordered if r.kind == DATA}
                live = self._live = LivePlacer(names)
            for m in live.push(msg):
                self._receive(m)
            return
        self._receive(msg)

    def _receive(self, msg: can.Message) -> None:
        """Queue one frame; process the queue when full or for an awaited alert."""
        pend = self._pending
        pend.append(msg)
        if len(pend) >= self.batch_size or msg.arbitration_id in self._prompt:
            self.flush()

    def choose_time_base(self, ids: Any, final: bool = False) -> bool:
        """``"auto"``: decide from the CAN IDs of the first frames; True when decided."""
        if not self._auto:
            return True
        arr = np.asarray(ids, dtype=np.int64) & ~EXT
        base = choose_time_base(arr, self.routes.sync_ids, self.routes.known_ids, final)
        if base is None:
            return False
        if base == "tick":
            self.time_source = "tick"
            self.engine.tick_time = True
        self._auto = False
        return True

    def sync_first_index(self, ids: Any) -> int:
        """Tick base, start of a stream: index of the first ``SN_Sync`` in ``ids`` (-1: none)."""
        eng = self.engine
        c = eng.counts
        if not eng.tick_time or eng.sync_tick is not None or \
                c.accepted + c.ignored + sum(c.rejected.values()) > 0:
            return -1
        return first_sync(np.asarray(ids, dtype=np.int64)[:AUTO_FRAMES] & ~EXT,
                          self.routes.sync_ids)

    def finish(self) -> None:
        """The input has ended: process every held frame."""
        live = self._live
        if live is not None:
            for m in live.finish():
                self._receive(m)
        with self._lock:
            if self._auto:
                self.choose_time_base([m.arbitration_id for m in self._pending], final=True)
        self.flush()

    def flush(self) -> None:
        """Validate, decode and buffer every queued frame (readers call it implicitly)."""
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
        """Validate, decode and buffer rows ``start:stop`` of ``frames``; returns the frames taken."""
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

    def places_arrivals(self) -> bool:
        """Whether a whole log fed now is placed in sample slots first."""
        return self.arrival_slots and not self._auto and not self.engine.tick_time

    def data_keys(self) -> list[int]:
        """Route keys (CAN ID | extended flag, bit 31) of the data messages."""
        return [r.key for r in self.routes.ordered if r.kind == DATA]

    def message_slot_times(self, arrivals: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
        """Route key -> data times (s) of the frames placed in sample slots, from arrival times."""
        placed = [(r.name, r.key, sl) for r in self.routes.ordered
                  if r.kind == DATA and arrivals.get(r.key, np.empty(0)).size
                  and (sl := arrival_slots(arrivals[r.key])) is not None]
        out: dict[int, np.ndarray] = {}
        for (name, key, sl), tm in zip(placed, place_messages([p[2] for p in placed])):
            if tm is not None:
                out[key] = tm
                self._slot_period = sl.period if not self._slot_period else \
                    min(self._slot_period, sl.period)
            self.arrival_stats[name] = {"period": sl.period, "missing": sl.missing,
                                        "retimed": tm is not None}
        return out

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

    def count_malformed(self, n: int) -> None:
        """Count ``n`` log lines/records that could not be parsed into frames."""
        with self._lock:
            self.engine.counts.rejected["malformed"] += n

    def on_error(self, exc: Exception) -> None:  # called by can.Notifier
        """Bus errors are counted as malformed input, never raised into the Notifier."""
        self.count_malformed(1)

    def stop(self) -> None:
        """Process the queued frames (part of the can.Listener interface)."""
        self.flush()

    # ---- results (each read processes the queue first)
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
        """``{"accepted", "rejected": {reason: n}, "ignored", "lost", "time_base"}``, with
        ``arrival_slots``, ``receive``, ``node_restarts``, ``tick_wraps``, ``unknown_page``, ``j1939``."""
        c = self.counts
        out: dict[str, object] = {"accepted": c.accepted, "rejected": dict(c.rejected),
                                  "ignored": c.ignored, "lost": c.lost,
                                  "time_base": "tick" if self.engine.tick_time else "timestamp"}
        clock = self.engine.clock
        self._live_stats()
        extra = {"node_restarts": clock.restarts, "tick_wraps": clock.wraps,
                 "arrival_slots": {k: dict(v) for k, v in self.arrival_stats.items()},
                 "receive": dict(self.receive_stats), "unknown_page": self.unknown_pages()}
        out.update((k, v) for k, v in extra.items() if v)   # the non-zero, non-empty ones
        if self.j1939 is not None:
            out["j1939"] = self.j1939.stats()
        return out

    def unknown_pages(self) -> dict[str, int]:
        """Multiplexed message -> accepted frames whose multiplexer value is no page of the DBC."""
        self.flush()
        return {r.name: r.pages.unknown for r in self.routes.ordered
                if r.pages is not None and r.pages.unknown}

    def per_message(self) -> dict[str, int]:
        """Accepted frames per DBC message name."""
        self.flush()
        return {r.name: r.accepted for r in self.routes.by_key.values()}

    def state(self) -> dict[str, object]:
        """Everything the validation carries from frame to frame (for comparisons)."""
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
        """Buffered ``channels`` (default all mapped; a map's mean removal applied) on a uniform
        grid of step ``dt`` (s; default the ``SN_Sync`` period in tick mode, else the median
        interval), NaN and gap records where samples are missing; the ``window`` (s, data time)
        ending at ``t_end`` (default everything, the newest sample)."""
        self.flush()
        self._live_stats()
        if dt is None and self.time_source == "tick":
            dt = self.engine.period
        t_start = None
        buf = self._buffer
        if window is not None:
            t_end = buf.latest_time() if t_end is None else t_end
            t_start = t_end - window
            if self._slot_period:
                # slot times a + k P: an edge sample stays in whatever P's last bits
                t_start -= 0.25 * self._slot_period
                t_end += 0.25 * self._slot_period
        al = buf.align(channels if channels is not None else self.channels, dt, t_start, t_end)
        for ch in self.mean_channels:
            if ch in al.values:
                v = al.values[ch]
                if (~np.isnan(v)).any():
                    al.values[ch] = v - float(np.nanmean(v))
        return al
