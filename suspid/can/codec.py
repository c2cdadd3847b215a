"""Channel values <-> CAN frames: precompiled signal packing, quantization, E2E.

:class:`MessageCodec` compiles, once per message, a small decoder of the selected signals
(one ``struct`` unpack for byte-aligned little-endian integers, else shifts and masks), far
faster than ``cantools.Message.decode`` and equal to its ``decode_choices=False`` values.

:class:`SensorEncoder` turns channel samples into the sensor frames of ``dbc/suspension.dbc``:
quantization, saturation to the DBC range (``Valid`` cleared, ``Saturated`` set), NaN as
``Valid = 0``, then the E2E counter and CRC.
"""
from __future__ import annotations

import math
import struct
import weakref
from dataclasses import dataclass, field
from typing import Callable, Iterable, Mapping, Sequence, cast

import can
from cantools.database.can import Database, Message

from suspid.can.crc import COUNTER_MODULUS, e2e_protect
from suspid.can.dbc import ALERT_MESSAGE, STATUS_MESSAGE, SYNC_MESSAGE, channel_signals, find_message, is_e2e
from suspid.errors import InputError, UsageError
from suspid.models import get_model


@dataclass(frozen=True)
class SignalSpec:
    """Bit layout and scaling of one signal (a compiled view of a cantools signal).

    ``start`` is the bit of the least significant bit in the payload read as one integer
    (little-endian for Intel signals, big-endian for Motorola ones); ``physical = raw * scale
    + offset``; ``raw_min``/``raw_max`` the DBC range, else the full bit range.
    """

    name: str
    start: int
    length: int
    signed: bool
    big_endian: bool
    is_float: bool
    scale: float
    offset: float
    raw_min: int
    raw_max: int


def signal_spec(message: Message, name: str) -> SignalSpec:
    """Compile the layout of signal ``name`` of ``message``."""
    sig = message.get_signal_by_name(name)
    length = sig.length
    big = sig.byte_order == "big_endian"
    start = sig.start
    if big:
        msb_left = 8 * (sig.start // 8) + (7 - sig.start % 8)
        start = 8 * message.length - 1 - (msb_left + length - 1)
    lo_full = -(1 << (length - 1)) if sig.is_signed else 0
    hi_full = (1 << (length - 1)) - 1 if sig.is_signed else (1 << length) - 1
    scale = float(sig.scale)
    offset = float(sig.offset)
    lo, hi = lo_full, hi_full
    if not sig.is_float and scale != 0:
        bounds = [None if b is None else (float(b) - offset) / scale
                  for b in (sig.minimum, sig.maximum)]
        if bounds[0] is not None and bounds[1] is not None and bounds[0] > bounds[1]:
            bounds.reverse()
        if bounds[0] is not None:
            lo = max(lo_full, math.ceil(bounds[0] - 1e-9))
        if bounds[1] is not None:
            hi = min(hi_full, math.floor(bounds[1] + 1e-9))
        if lo > hi:  # inconsistent DBC range: fall back to the bit range
            lo, hi = lo_full, hi_full
    return SignalSpec(name, start, length, bool(sig.is_signed), big, bool(sig.is_float),
                      scale, offset, lo, hi)


class MessageCodec:
    """Precompiled decoder (and encoder) of the ``signals`` of one DBC message (default: every
    non-multiplexed signal).

    ``names`` is the signal order of :meth:`decode` / :meth:`unpack_raw` results; ``fast``
    is ``True`` if decoding uses one ``struct`` unpack.
    """

    def __init__(self, message: Message, signals: Sequence[str] | None = None) -> None:
        self.message = message
        self.name: str = message.name
        self.frame_id: int = message.frame_id
        self.length: int = message.length
        self.is_extended: bool = message.is_extended_frame
        self.e2e: bool = is_e2e(message)
        if signals is None:
            signals = [s.name for s in message.signals if not s.multiplexer_ids]
        self.names: tuple[str, ...] = tuple(signals)
        self.specs: tuple[SignalSpec, ...] = tuple(signal_spec(message, n) for n in self.names)
        self.fast = False
        self.unpack_raw: Callable[[bytes], tuple] = self._compile_unpack(scaled=False)
        self.decode: Callable[[bytes], tuple] = self._compile_unpack(scaled=True)
        #: ``(mask, start bit)`` per signal of an all-Intel integer layout (``None``: encoded by
        #: cantools)
        self._pack = None if any(s.big_endian or s.is_float for s in self.specs) else \
            [((1 << s.length) - 1, s.start) for s in self.specs]

    # ---- decoding --------------------------------------------------------------------
    def _compile_unpack(self, scaled: bool) -> Callable[[bytes], tuple]:
        """Generate the decoder of the selected signals (``scaled``: physical values); generated
        code is markedly faster per frame than a loop (docs/performance.md)."""
        specs = self.specs
        aligned = all(not s.big_endian and s.start % 8 == 0 and s.length in (8, 16, 32, 64)
                      and (not s.is_float or s.length in (32, 64)) for s in specs)
        ns: dict[str, object] = {"_fb": int.from_bytes, "_unpack": struct.unpack_from}
        if aligned and specs:
            order = sorted(range(len(specs)), key=lambda i: specs[i].start)
            fmt = "<"
            pos = 0
            codes = {8: "b", 16: "h", 32: "i", 64: "q"}
            for i in order:
                s = specs[i]
                byte = s.start // 8
                if byte < pos:  # overlapping (multiplexed) signals: no struct path
                    aligned = False
                    break
                if byte > pos:
                    fmt += f"{byte - pos}x"
                if s.is_float:
                    fmt += "f" if s.length == 32 else "d"
                else:
                    c = codes[s.length]
                    fmt += c if s.signed else c.upper()
                pos = byte + s.length // 8
        if aligned and specs:
            st = struct.Struct(fmt)
            ns["_st"] = st.unpack_from
            inv = [0] * len(specs)
            for k, i in enumerate(order):
                inv[i] = k
            lines = ["def _dec(data):", "    v = _st(data)"]
            terms = []
            for i, s in enumerate(specs):
                term = f"v[{inv[i]}]"
                if scaled and not s.is_float:
                    term = self._scale_term(term, s)
                terms.append(term)
            lines.append(f"    return ({', '.join(terms)}{',' if len(terms) == 1 else ''})")
            self.fast = True
        else:
            lines = ["def _dec(data):"]
            if any(not s.big_endian and not s.is_float for s in specs):
                lines.append("    vl = _fb(data, 'little')")
            if any(s.big_endian and not s.is_float for s in specs):
                lines.append("    vb = _fb(data, 'big')")
            terms = []
            for i, s in enumerate(specs):
                if s.is_float:
                    if s.start % 8 or s.big_endian:
                        ns[f"_cd{i}"] = self.message
                        lines.append(f"    f{i} = _cd{i}.decode(bytes(data), decode_choices=False, "
                                     f"scaling=False)[{s.name!r}]")
                    else:
                        lines.append(f"    f{i} = _unpack('<{'f' if s.length == 32 else 'd'}', "
                                     f"data, {s.start // 8})[0]")
                    terms.append(f"f{i}")
                    continue
                src = "vb" if s.big_endian else "vl"
                mask = (1 << s.length) - 1
                lines.append(f"    r{i} = ({src} >> {s.start}) & {mask}")
                if s.signed:
                    lines.append(f"    r{i} -= (r{i} & {1 << (s.length - 1)}) << 1")
                terms.append(self._scale_term(f"r{i}", s) if scaled else f"r{i}")
            lines.append(f"    return ({', '.join(terms)}{',' if len(terms) == 1 else ''})")
        exec("\n".join(lines), ns)  # noqa: S102 - generated from the DBC layout only
        return cast("Callable[[bytes], tuple]", ns["_dec"])

    @staticmethod
    def _scale_term(term: str, s: SignalSpec) -> str:
        if s.scale == 1.0 and s.offset == 0.0:
            return term
        if s.offset == 0.0:
            return f"{term} * {s.scale!r}"
        return f"{term} * {s.scale!r} + {s.offset!r}"

    # ---- encoding --------------------------------------------------------------------
    def pack_raw(self, raw: Sequence[int]) -> bytearray:
        """Payload with the raw values ``raw`` (in :attr:`names` order); other bits zero."""
        if self._pack is not None:
            v = 0
            for r, (mask, start) in zip(raw, self._pack):
                v |= (r & mask) << start
            return bytearray(v.to_bytes(self.length, "little"))
        data = {s.name: r for s, r in zip(self.specs, raw)}
        for sig in self.message.signals:
            data.setdefault(sig.name, 0)
        return bytearray(self.message.encode(data, scaling=False, strict=False))

    def to_raw(self, index: int, value: float) -> tuple[int, int]:
        """Quantize a physical value for signal ``index``: ``(raw, status)``, raw rounded and
        clamped to the DBC range (0 for NaN), status 0 valid, 1 missing, 2 saturated."""
        s = self.specs[index]
        if value != value:  # NaN
            return 0, 1
        x = (value - s.offset) / s.scale
        if x != x or x in (math.inf, -math.inf):
            return 0, 1
        raw = int(math.floor(x + 0.5))
        if raw < s.raw_min:
            return s.raw_min, 2
        if raw > s.raw_max:
            return s.raw_max, 2
        return raw, 0


# ---- the suspid sensor set ---------------------------------------------------------------
@dataclass
class _Slot:
    """One channel carried by a message of the sensor set."""

    channel: str
    index: int          # position in the message codec
    valid_index: int    # position of the <Name>Valid bit, -1 if none


@dataclass
class _MessagePlan:
    codec: MessageCodec
    slots: list[_Slot] = field(default_factory=list)
    saturated_index: int = -1


class SensorEncoder:
    """Encode samples of model ``channels`` (and road columns) into the sensor frames of a
    suspid DBC (messages by ``SuspidChannel`` for ``model_name``; those carrying none of the
    channels are not sent; a channel the DBC does not carry raises).

    ``plans`` are the sensor messages sent each sample, in order; ``saturated`` counts the
    samples clamped per channel.
    """

    def __init__(self, db: Database, model_name: str, channels: Iterable[str]) -> None:
        self.db = db
        self.model_name = model_name
        wanted = list(dict.fromkeys(channels))
        mapping = channel_signals(db, model_name)
        if not mapping:
            raise InputError(f"{getattr(db, 'suspid_path', 'DBC')}: no signal has a SuspidChannel "
                             f"attribute for model {model_name}; expected suspid's suspension.dbc")
        by_channel = {ch: (m, s) for ch, m, s in mapping}
        missing = [c for c in wanted if c not in by_channel]
        if missing:
            raise UsageError(f"the DBC carries no signal for channel(s) {', '.join(missing)} of "
                             f"model {model_name}; it carries {', '.join(by_channel)}")
        per_msg: dict[str, list[tuple[str, str]]] = {}
        for ch in wanted:
            m, s = by_channel[ch]
            per_msg.setdefault(m, []).append((ch, s))
        self.plans: list[_MessagePlan] = []
        for msg in sorted((db.get_message_by_name(n) for n in per_msg), key=lambda m: m.frame_id):
            pairs = per_msg[msg.name]
            sig_names = [s for _, s in pairs]
            present = {x.name for x in msg.signals}
            extra = [f"{s}Valid" for s in sig_names if f"{s}Valid" in present]
            has_sat = "Saturated" in present
            names = sig_names + extra + (["Saturated"] if has_sat else [])
            codec = MessageCodec(msg, names)
            slots = [_Slot(ch, k, names.index(f"{s}Valid") if f"{s}Valid" in names else -1)
                     for k, (ch, s) in enumerate(pairs)]
            self.plans.append(_MessagePlan(codec, slots, names.index("Saturated") if has_sat else -1))
        self.sync = MessageCodec(find_message(db, SYNC_MESSAGE), ["Tick", "PeriodUs"])
        self.saturated: dict[str, int] = {}

    def sync_frame(self, tick: int, period_s: float) -> tuple[int, bytearray]:
        """``(frame_id, payload)`` of the ``SN_Sync`` frame of sample ``tick``."""
        period_us = min(65535, max(1, int(round(period_s * 1e6))))
        data = self.sync.pack_raw((tick & 0xFFFFFFFF, period_us))
        e2e_protect(data, self.sync.frame_id, tick % COUNTER_MODULUS)
        return self.sync.frame_id, data

    def sample_frames(self, tick: int, values: Mapping[str, float]
                      ) -> list[tuple[int, bytearray]]:
        """``(frame_id, payload)`` of the sensor frames of sample ``tick`` (E2E counter ``tick
        mod 15``); ``values``: channel -> value (SI), absent or NaN ones sent ``Valid = 0``."""
        counter = tick % COUNTER_MODULUS
        out = []
        for plan in self.plans:
            codec = plan.codec
            raw = [0] * len(codec.specs)
            sat = 0
            for slot in plan.slots:
                v = values.get(slot.channel, math.nan)
                r, status = codec.to_raw(slot.index, float(v))
                raw[slot.index] = r
                if slot.valid_index >= 0:
                    raw[slot.valid_index] = 1 if status == 0 else 0
                if status == 2:
                    sat = 1
                    self.saturated[slot.channel] = self.saturated.get(slot.channel, 0) + 1
            if plan.saturated_index >= 0:
                raw[plan.saturated_index] = sat
            data = codec.pack_raw(raw)
            if codec.e2e:
                e2e_protect(data, codec.frame_id, counter)
            out.append((codec.frame_id, data))
        return out


def make_message(frame_id: int, data: bytes | bytearray, timestamp: float,
                 is_extended: bool = False, channel: str | int | None = None) -> can.Message:
    """A python-can data frame (``check=False``: our own payloads are well formed)."""
    return can.Message(timestamp=timestamp, arbitration_id=frame_id, is_extended_id=is_extended,
                       data=data, channel=channel, check=False)


# ---- status and alert ----------------------------------------------------------------------
#: SN_Status.State values
STATE_INIT, STATE_RUNNING, STATE_DEGRADED, STATE_BUSOFF_RECOVERED, STATE_STOPPING = range(5)
#: SN_Status.FaultFlags bits
FAULT_BITS = {"loss": 0, "burst": 1, "stuck": 2, "bitflip": 3, "late": 4, "busoff": 5,
              "saturation": 6}
#: SUSPID_Alert parameter kinds (parameter ids: the DBC's ``ParamId`` value table)
PARAM_KINDS = {"mass": 0, "inertia": 1, "damping": 2, "stiffness": 3, "length": 4}
_KIND_PREFIX = {0: "Mass", 1: "Inertia", 2: "Damping", 3: "Stiffness", 4: "Length"}
SEVERITIES = {"info": 0, "warning": 1, "critical": 2, "forecast": 3}


_STATUS_CODECS: "weakref.WeakKeyDictionary[Database, MessageCodec]" = weakref.WeakKeyDictionary()


def encode_status(db: Database, counter: int, state: int, sample_rate: float, fault_flags: int,
                  busoff_count: int, sensor_set: int) -> tuple[int, bytearray]:
    """``(frame_id, payload)`` of an ``SN_Status`` frame (E2E protected)."""
    codec = _STATUS_CODECS.get(db)
    if codec is None:
        codec = MessageCodec(find_message(db, STATUS_MESSAGE),
                             ["State", "SampleRate", "FaultFlags", "BusOffCount", "SensorSet"])
        _STATUS_CODECS[db] = codec
    data = codec.pack_raw((state, int(round(sample_rate)) & 0xFFFF, fault_flags & 0xFFFF,
                           min(255, busoff_count), sensor_set))
    e2e_protect(data, codec.frame_id, counter)
    return codec.frame_id, data


def _choices(db: Database, signal: str) -> dict[str, int]:
    """``name -> value`` of a ``SUSPID_Alert`` signal's value table in the DBC."""
    sig = find_message(db, ALERT_MESSAGE).get_signal_by_name(signal)
    return {str(v): int(k) for k, v in (sig.choices or {}).items()}


def encode_alert(db: Database, model_name: str, parameter: str, value: float, nominal: float,
                 severity: str = "warning", counter: int = 0) -> can.Message:
    """The ``SUSPID_Alert`` frame an estimator sends for a parameter drop of ``parameter``
    (``c1``, ...) of ``model_name``: identified and nominal ``value`` (SI, clamped to the DBC
    range of the kind), ``severity`` of :data:`SEVERITIES`, E2E alive ``counter``."""
    param_ids = _choices(db, "ParamId")
    if parameter not in param_ids:
        raise UsageError(f"alert parameter {parameter!r} unknown; expected one of {', '.join(param_ids)}")
    if severity not in SEVERITIES:
        raise UsageError(f"alert severity {severity!r} unknown; expected one of {', '.join(SEVERITIES)}")
    msg = find_message(db, ALERT_MESSAGE)
    model = get_model(model_name)
    model_ids = _choices(db, "Model")
    if model_ids.get(model_name) != model.alert_id:
        raise UsageError(f"model {model_name} has no SUSPID_Alert.Model id in the DBC (its alert_id "
                         f"is {model.alert_id}; the DBC lists {model_ids}); give a DBC that does")
    kind = PARAM_KINDS[model.spec(parameter).kind]
    prefix = _KIND_PREFIX[kind]
    sig_v = msg.get_signal_by_name(f"{prefix}Value")
    if sig_v.minimum is None or sig_v.maximum is None:
        raise InputError(f"DBC: {ALERT_MESSAGE}.{sig_v.name} has no range; expected [min|max] "
                         "to clamp alert values to")
    lo, hi = float(sig_v.minimum), float(sig_v.maximum)
    data = {"CRC": 0, "Counter": 0, "Severity": SEVERITIES[severity],
            "Model": model.alert_id, "ParamId": param_ids[parameter], "ParamKind": kind,
            f"{prefix}Value": min(hi, max(lo, float(value))),
            f"{prefix}Nominal": min(hi, max(lo, float(nominal)))}
    payload = bytearray(msg.encode(data, strict=False))
    e2e_protect(payload, msg.frame_id, counter)
    return make_message(msg.frame_id, payload, 0.0)


def decode_alert(db: Database, data: bytes | bytearray) -> dict[str, object]:
    """Decode an ``SUSPID_Alert`` payload to ``{model, parameter, value, nominal, severity}``."""
    msg = find_message(db, ALERT_MESSAGE)
    # one message, decode_choices=False, no container: a flat mapping of signal -> number
    d = cast("Mapping[str, float]", msg.decode(bytes(data), decode_choices=False))
    kind = int(d["ParamKind"])
    prefix = _KIND_PREFIX.get(kind)
    if prefix is None:
        raise InputError(f"alert frame: ParamKind {kind} unknown; expected 0..4")
    names = {v: k for k, v in _choices(db, "ParamId").items()}
    models = {v: k for k, v in _choices(db, "Model").items()}
    sev = {v: k for k, v in SEVERITIES.items()}
    return {"model": models.get(int(d["Model"]), str(d["Model"])),
            "parameter": names.get(int(d["ParamId"]), str(d["ParamId"])),
            "value": float(d[f"{prefix}Value"]), "nominal": float(d[f"{prefix}Nominal"]),
            "severity": sev.get(int(d["Severity"]), str(d["Severity"]))}
