"""How the decoder treats each CAN ID of the DBC (data, ``SN_Sync``, ``SN_Status``,
``SUSPID_Alert``): its route (length, E2E check, decoders, ring, per-message state), and the
batch path's lookup tables. A DBC message without a mapped channel has no route (``ignored``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence, cast

import numpy as np
from cantools.database.can import Database, Message

from estimator.decode.buffer import RollingBuffer, Source
from estimator.decode.pages import PageSink, PageSplit
from estimator.decode.rules.e2e import Payload, crc_start
from estimator.decode.vector import RowsFn, compile_raw, compile_vector_row
from suspid.can.codec import MessageCodec, signal_spec
from suspid.can.dbc import ALERT_MESSAGE, STATUS_MESSAGE, SYNC_MESSAGE, find_message, is_e2e
from suspid.can.signal_map import SignalMap, SignalMapping
from suspid.models import SuspensionModel

#: extended-frame flag of a route key (CAN ID | flag)
EXT = 1 << 31
#: route kinds
DATA, SYNC, STATUS, ALERT = range(4)

#: payload -> decoded values
Unpack = Callable[[Payload], tuple]


def route_key(frame_id: int, extended: bool) -> int:
    """Route key of a frame: CAN ID | :data:`EXT` for extended frames."""
    return frame_id | (EXT if extended else 0)


def _decoded_elsewhere(data: Payload) -> tuple:
    """``decode`` of data messages (``row``/``vrow``) and SUSPID_Alert (``decode_alert``)."""
    return ()


@dataclass(eq=False)
class Route:
    """How to validate and store one CAN ID, and its message's state."""

    name: str
    kind: int
    dlc: int
    e2e: bool                                  # E2E protected (CRC and alive counter)
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
    pages: PageSplit | None = None  # multiplexed data message: stored page by page


def compile_row(msg: Message, maps: Sequence[SignalMapping]) -> Unpack:
    """``row(payload) -> (value per mapping, ...)``, NaN where a ``<Signal>Valid`` bit is 0."""
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


def compile_sync(codec: MessageCodec) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None:
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


def _multiplexer_of(msg: Message, signal: str) -> str | None:
    """The multiplexer of a multiplexed signal of ``msg`` (``None``: in every frame)."""
    sig = msg.get_signal_by_name(signal)
    return sig.multiplexer_signal if sig.multiplexer_ids else None


def _page_split(msg: Message, name: str, maps: Sequence[SignalMapping],
                buffer: RollingBuffer) -> PageSplit:
    """The rings of a multiplexed message's mapped signals, one per set of pages."""
    groups: dict[tuple[str, tuple[int, ...]] | None, list[SignalMapping]] = {}
    for m in maps:
        mux = _multiplexer_of(msg, m.signal)
        ids = tuple(sorted(msg.get_signal_by_name(m.signal).multiplexer_ids or ()))
        groups.setdefault((mux, ids) if mux is not None else None, []).append(m)
    muxes = list(dict.fromkeys(g[0] for g in groups if g is not None))
    sinks = []
    for g, gm in groups.items():
        ring = name if g is None else f"{name}[{g[0]}={','.join(str(i) for i in g[1])}]"
        src = buffer.source(ring, [m.channel for m in gm], group=name)
        sinks.append(PageSink(src, compile_row(msg, gm), compile_vector_row(msg, gm),
                              -1 if g is None else muxes.index(g[0]),
                              frozenset(g[1]) if g is not None else frozenset()))
    return PageSplit(msg, muxes, sinks)


def model_channels(model: SuspensionModel) -> list[str]:
    """Every channel a map may target: measured channels, roads and road velocities."""
    return list(model.channels) + list(model.roads) + [f"{r}_dot" for r in model.roads]


class Routes:
    """The routes of a DBC and validated signal map, and the batch path's lookup tables."""

    def __init__(self, db: Database, signal_map: SignalMap, buffer: RollingBuffer) -> None:
        self.by_key: dict[int, Route] = {}
        self.known: set[int] = {route_key(msg.frame_id, msg.is_extended_frame)
                                for msg in db.messages}
        # by frame key, not name: a standard and an extended frame may share a name
        per_msg: dict[int, tuple[Message, list[SignalMapping]]] = {}
        for m in signal_map.mappings:
            msg = find_message(db, m.message, signal_map.source)
            per_msg.setdefault(route_key(msg.frame_id, msg.is_extended_frame),
                               (msg, []))[1].append(m)
        names = [msg.name for msg, _ in per_msg.values()]
        for msg, maps in per_msg.values():
            name = msg.name
            if names.count(name) > 1:
                name = f"{name}@{msg.frame_id:#x}{'x' if msg.is_extended_frame else ''}"
            if any(_multiplexer_of(msg, m.signal) for m in maps):
                route = self._add(msg, DATA, _decoded_elsewhere)
                route.pages = _page_split(msg, name, maps, buffer)
            else:
                src = buffer.source(name, [m.channel for m in maps])
                route = self._add(msg, DATA, _decoded_elsewhere, src, compile_row(msg, maps))
                route.vrow = compile_vector_row(msg, maps)
            route.name = name
        for special, kind in ((SYNC_MESSAGE, SYNC), (STATUS_MESSAGE, STATUS),
                              (ALERT_MESSAGE, ALERT)):
            try:
                msg = db.get_message_by_name(special)
            except KeyError:
                continue
            if route_key(msg.frame_id, msg.is_extended_frame) in self.by_key:
                continue
            if kind == SYNC:
                codec = MessageCodec(msg, ["Tick", "PeriodUs"])
                # the codec's unpackers are typed for bytes and take any buffer
                route = self._add(msg, kind, cast(Unpack, codec.decode))
                route.vsync = compile_sync(codec)
                continue
            if kind == STATUS:
                dec = cast(Unpack, MessageCodec(msg, ["State", "SampleRate", "FaultFlags",
                                                      "BusOffCount", "SensorSet"]).decode)
            else:
                dec = _decoded_elsewhere  # decode_alert, with cantools (multiplexed, rare)
            self._add(msg, kind, dec)
        rl = sorted(self.by_key.values(), key=lambda r: (r.kind != SYNC, not r.e2e))
        self.ordered = rl
        order = sorted(range(len(rl)), key=lambda i: rl[i].key)
        self.keys = np.array([rl[i].key for i in order], dtype=np.int64)
        self.num = np.array(order, dtype=np.int64)
        self.ignored_keys = np.array(sorted(self.known - set(self.by_key)), dtype=np.int64)
        self.dlc = np.array([r.dlc for r in rl], dtype=np.int64)
        self.e2e = np.array([r.e2e for r in rl], dtype=bool)
        self.start = np.array([r.start_reg for r in rl], dtype=np.uint8)
        self.data_e2e = np.array([r.kind == DATA and r.e2e for r in rl])
        self.tick_e2e = np.array([r.kind in (STATUS, ALERT) and r.e2e
                                  for r in rl])
        self.alert_ids = frozenset(r.key & ~EXT for r in rl if r.kind == ALERT)
        self.known_ids = np.array(sorted(k & ~EXT for k in self.known), dtype=np.int64)
        self.sync_ids = np.array(sorted(r.key & ~EXT for r in rl if r.kind == SYNC),
                                 dtype=np.int64)

    def _add(self, msg: Message, kind: int, decode: Unpack, source: Source | None = None,
             row: Unpack | None = None) -> Route:
        e2e = is_e2e(msg)
        route = Route(msg.name, kind, msg.length, e2e, decode, source, row)
        route.key = route_key(msg.frame_id, msg.is_extended_frame)
        route.start_reg = crc_start(msg.frame_id) if e2e else 0
        self.by_key[route.key] = route
        return route
