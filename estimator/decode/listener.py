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

Feed it like any python-can listener: ``can.Notifier(bus, [listener])`` on a live bus, or
:func:`estimator.decode.replay.feed` for a log (one loop calling ``on_message_received``:
no reader thread and queue hand-off, so replay runs at decode speed and is deterministic;
:class:`estimator.decode.replay.ReplayBus` runs the same log through a Notifier).
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Literal, Sequence

import can
import numpy as np
from cantools.database.can import Database, Message

from estimator.decode.buffer import Aligned, RollingBuffer, Source
from suspid.can.codec import MessageCodec, decode_alert, signal_spec
from suspid.can.crc import COUNTER_MODULUS, make_e2e_checker
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

_DATA, _SYNC, _STATUS, _ALERT = range(4)


@dataclass(eq=False)
class _Route:
    """How to validate and store one CAN ID."""

    name: str
    kind: int
    dlc: int
    check: Callable[[bytes], bool] | None   # E2E CRC checker, None if not protected
    decode: Callable[[bytes], tuple]         # special messages
    source: Source | None = None
    row: Callable[[bytes], tuple] | None = None   # data messages: payload -> channel values
    last_c: int = -1
    last_ts: float = 0.0
    period: float = 0.0
    accepted: int = 0
    last_arrival: float = 0.0   # tick mode: frame timestamp (arrival) of the last frame
    sync_n: int = -1            # tick mode: SN_Sync frames seen at the last frame


def _compile_row(msg: Message, maps: Sequence[SignalMapping]) -> Callable[[bytes], tuple]:
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
    return ns["_row"]  # type: ignore[return-value]


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
    time_source : {"timestamp", "tick"}
        Data time from the frame timestamps, or from the node's ``SN_Sync`` tick.
    max_counter_delta : int
        Largest accepted counter advance (1 = no frame may be lost).
    stale_window : int
        Counter steps back still read as an old (late or duplicate) frame rather than a jump.

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
    """

    def __init__(self, model: str | SuspensionModel, dbc: str | Path | Database | None = None,
                 signal_map: SignalMapLike = None, *, capacity: int = 1 << 16,
                 growable: bool = False,
                 time_source: Literal["timestamp", "tick"] = "timestamp",
                 max_counter_delta: int = 4, stale_window: int = 5) -> None:
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
        if time_source not in ("timestamp", "tick"):
            raise UsageError(f"time_source must be 'timestamp' or 'tick', got {time_source!r}")
        self.time_source = time_source
        if not 1 <= max_counter_delta <= COUNTER_MODULUS - 2:
            raise UsageError(f"max_counter_delta must be 1..13, got {max_counter_delta}")
        self.max_counter_delta = max_counter_delta
        self.stale_window = max(0, min(stale_window, COUNTER_MODULUS - 1 - max_counter_delta))
        self.buffer = RollingBuffer(capacity, growable)
        self.counts = FrameCounts()
        self.node_status: dict[str, object] = {}
        self.alerts: list[dict[str, object]] = []
        self.period: float | None = None
        self.mean_channels = [m.channel for m in smap.mappings if m.remove_mean]
        self.frames = 0
        self.time_resyncs = 0
        self._last_ts = -sys.float_info.max  # any finite time passes the first check
        self._time_rejects = 0
        self._sync_tick: int | None = None
        self._sync_n = 0
        self._routes: dict[int, _Route] = {}
        self._known: set[int] = set()
        self._rejected = self.counts.rejected
        self._tick_time = time_source == "tick"
        self._build_routes()

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
            src = self.buffer.source(name, [m.channel for m in maps])
            self._add_route(msg, _DATA, bytes, src, _compile_row(msg, maps))
        for special, kind in ((SYNC_MESSAGE, _SYNC), (STATUS_MESSAGE, _STATUS),
                              (ALERT_MESSAGE, _ALERT)):
            try:
                msg = db.get_message_by_name(special)
            except KeyError:
                continue
            if self._key(msg.frame_id, msg.is_extended_frame) in self._routes:
                continue
            if kind == _SYNC:
                dec = MessageCodec(msg, ["Tick", "PeriodUs"]).decode
            elif kind == _STATUS:
                dec = MessageCodec(msg, ["State", "SampleRate", "FaultFlags", "BusOffCount",
                                         "SensorSet"]).decode
            else:
                dec = bytes  # decoded with cantools (multiplexed, rare)
            self._add_route(msg, kind, dec)
        if self.time_source == "tick" and not any(r.kind == _SYNC for r in self._routes.values()):
            raise UsageError(f"time_source 'tick' needs message {SYNC_MESSAGE} in the DBC "
                             f"{getattr(self.db, 'suspid_path', '')}")

    def _add_route(self, msg: Message, kind: int, decode: Callable[[bytes], tuple],
                   source: Source | None = None,
                   row: Callable[[bytes], tuple] | None = None) -> None:
        check = make_e2e_checker(msg.frame_id, msg.length) if is_e2e(msg) else None
        route = _Route(msg.name, kind, msg.length, check, decode, source, row)
        self._routes[self._key(msg.frame_id, msg.is_extended_frame)] = route

    # ---- the hot path ------------------------------------------------------------------
    def on_message_received(self, msg: can.Message) -> None:
        """Validate one frame; decode and buffer it, or count why it was rejected."""
        self.frames += 1
        rejected = self._rejected
        if msg.is_error_frame or msg.is_remote_frame:
            rejected["frame_type"] += 1
            return
        ts = msg.timestamp
        if not self._last_ts <= ts < _INF:  # one chained compare: backwards, NaN or inf
            if not -_INF < ts < _INF:
                rejected["time"] += 1  # NaN/inf: never a data time, never a re-anchor
                return
            self._time_rejects += 1
            if self._time_rejects < TIME_RESYNC:
                rejected["time"] += 1
                return
            self.time_resyncs += 1  # the clock was reset: re-anchor on this frame
        self._time_rejects = 0
        self._last_ts = ts
        key = msg.arbitration_id | _EXT if msg.is_extended_id else msg.arbitration_id
        route = self._routes.get(key)
        if route is None:
            if key in self._known:
                self.counts.ignored += 1
            else:
                rejected["unknown_id"] += 1
            return
        data = msg.data
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
                        ts = int(tick) * period_us * 1e-6
                elif route.kind == _DATA and self._sync_tick is not None and self.period:
                    if (route.sync_n == self._sync_n and last >= 0
                            and arrival - route.last_arrival
                            > COUNTER_MODULUS // 2 * max(route.period, self.period)):
                        # no SN_Sync since this message's last frame, and a silence longer
                        # than the counter can match (a link closed and reopened): the last
                        # tick is stale and would place the frame in the past
                        rejected["no_sync"] += 1
                        return
                    d = (self._sync_tick - c) % COUNTER_MODULUS
                    tick = self._sync_tick - d if d <= COUNTER_MODULUS // 2 else \
                        self._sync_tick - d + COUNTER_MODULUS
                    ts = tick * self.period
                route.last_arrival = arrival
                route.sync_n = self._sync_n
            if last >= 0 and (c - last) % COUNTER_MODULUS != 1:
                if not self._counter_gap(route, c, last, ts):
                    return
            elif last >= 0:
                el = ts - route.last_ts
                per = route.period
                if per > 0 and el > 1.5 * per:
                    # advance 1 mod 15 after a silence: 15, 30, ... frames were lost that
                    # the 4-bit counter cannot show (bus-off, burst); the time can
                    steps = int(el / per + 0.5)
                    if steps % COUNTER_MODULUS == 1:
                        self.counts.lost += steps - 1
                elif el > 0:
                    route.period = el if per <= 0 else 0.9 * per + 0.1 * el
            route.last_c = c
            route.last_ts = ts
        if route.kind == _DATA:
            if self._tick_time:
                if self._sync_tick is None or c < 0:
                    rejected["no_sync"] += 1
                    return
                # ts is the data time matched through the counter above
            route.source.push(ts, route.row(data))  # type: ignore[union-attr]
        elif not self._special(route, data, ts):
            return
        route.accepted += 1
        self.counts.accepted += 1

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
            self.counts.lost += (steps if matched else delta) - 1
            return True
        if steps >= 2 and (steps - delta) % COUNTER_MODULUS == 0:
            self.counts.lost += steps - 1
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

    def _special(self, route: _Route, data: bytes, ts: float) -> bool:
        """SN_Sync, SN_Status and SUSPID_Alert frames; ``False`` if rejected."""
        if route.kind == _SYNC:
            tick, period_us = route.decode(data)
            self._sync_tick = int(tick)
            self._sync_n += 1
            if period_us > 0:
                self.period = period_us * 1e-6
        elif route.kind == _STATUS:
            state, rate, flags, busoff, sset = route.decode(data)
            self.node_status = {"t": ts, "state": int(state), "sample_rate": float(rate),
                                "fault_flags": int(flags), "busoff_count": int(busoff),
                                "sensor_set": int(sset)}
        else:
            try:
                alert = decode_alert(self.db, data)
            except Exception:  # an unknown ParamKind: a corrupted but CRC-valid alert
                self._rejected["crc"] += 1
                return False
            alert["t"] = ts
            self.alerts.append(alert)
        return True

    def count_malformed(self, n: int) -> None:
        """Count ``n`` log lines/records that could not be parsed into frames."""
        self.counts.rejected["malformed"] += n

    def on_error(self, exc: Exception) -> None:  # called by can.Notifier
        """Bus errors are counted as malformed input, never raised into the Notifier."""
        self.counts.rejected["malformed"] += 1

    def stop(self) -> None:
        """Nothing to release (part of the can.Listener interface)."""

    # ---- results -----------------------------------------------------------------------
    def frame_stats(self) -> dict[str, object]:
        """``{"accepted": N, "rejected": {reason: n}, "ignored": n, "lost": n}`` (JSON-ready)."""
        c = self.counts
        return {"accepted": c.accepted, "rejected": dict(c.rejected), "ignored": c.ignored,
                "lost": c.lost}

    def per_message(self) -> dict[str, int]:
        """Accepted frames per DBC message name."""
        return {r.name: r.accepted for r in self._routes.values()}

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
        if dt is None and self.time_source == "tick":
            dt = self.period
        t_start = None
        if window is not None:
            end = self.buffer.latest_time() if t_end is None else t_end
            t_start = end - window
            t_end = end
        al = self.buffer.align(channels if channels is not None else self.channels, dt,
                               t_start, t_end)
        for ch in self.mean_channels:
            if ch in al.values:
                v = al.values[ch]
                if (~np.isnan(v)).any():
                    al.values[ch] = v - float(np.nanmean(v))
        return al
