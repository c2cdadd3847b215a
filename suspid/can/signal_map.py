"""Map signals of a user's DBC onto model channels (the "real logger hookup").

One mapping reads like an assignment, ``x1_ddot = gnss_imu.AccelerationX - 9.81`` or
``x2 = 0x123.Height * 0.001``: ``CHANNEL = [SCALE *] [-] MESSAGE.SIGNAL [* SCALE] [(+|-)
OFFSET | - mean]``, i.e. ``channel = scale * signal + offset`` in the channel's SI unit
(grammar and examples in docs/can.md). Given by ``--map`` (repeatable), the ``[map]`` table
of a ``--config`` file, or a ``.toml``/``.json`` signal-map file::

    dbc = "canmod-gps.dbc"          # optional, relative to the file
    [map]
    x1_ddot = "gnss_imu.AccelerationX - 9.81"
    # x1_ddot = { message = "gnss_imu", signal = "AccelerationX", scale = 1.0, offset = -9.81 }
"""
from __future__ import annotations

import json
import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Iterable, Sequence, Union

from suspid.can.conventions import channel_signals, find_message
from suspid.errors import InputError, UsageError
from suspid.io.csvio import normalize_unit, si_units
from suspid.models.base import SuspensionModel

if TYPE_CHECKING:
    from cantools.database.can import Database

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_RE = re.compile(
    rf"""^\s*(?P<channel>[A-Za-z_]\w*)\s*=\s*
    (?:(?P<pre>{_NUM})\s*\*\s*)?
    (?P<neg>-\s*)?
    (?P<message>[A-Za-z_]\w*|0[xX][0-9A-Fa-f]+|\d+)\.(?P<signal>[A-Za-z_]\w*)\s*
    (?:\*\s*(?P<post>{_NUM})\s*)?
    (?:(?P<sign>[-+])\s*(?:(?P<off>(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)|(?P<mean>mean)|\(\s*(?P<poff>{_NUM})\s*\))\s*)?
    $""",
    re.VERBOSE,
)


@dataclass(frozen=True)
class SignalMapping:
    """``channel = scale * MESSAGE.SIGNAL + offset`` (offset ``"mean"`` removes the mean);
    ``channel`` a model channel or road column, ``message`` a DBC message name or frame ID."""

    channel: str
    message: str
    signal: str
    scale: float = 1.0
    offset: Union[float, str] = 0.0

    @property
    def remove_mean(self) -> bool:
        """``True`` if the offset is the data's mean."""
        return self.offset == "mean"

    def __str__(self) -> str:
        s = f"{self.channel}="
        if self.scale != 1.0:
            s += f"{self.scale:g}*"
        s += f"{self.message}.{self.signal}"
        if self.remove_mean:
            s += "-mean"
        elif self.offset:
            s += f"{float(self.offset):+g}"
        return s


_RE_REVERSED = re.compile(
    r"""^\s*(?P<message>[A-Za-z_]\w*|0[xX][0-9A-Fa-f]+|\d+)\.(?P<signal>[A-Za-z_]\w*)\s*=\s*
    (?P<channel>[A-Za-z_]\w*)\s*(?P<rest>.*)$""",
    re.VERBOSE,
)


def parse_mapping(text: str, where: str = "--map") -> SignalMapping:
    """Parse one ``CHANNEL=MESSAGE.SIGNAL...`` mapping (or ``MESSAGE.SIGNAL=CHANNEL...``).

    Raises
    ------
    UsageError
        Naming ``where`` (the option or file) and showing the expected form.
    """
    r = _RE_REVERSED.match(text)
    if r and not _RE.match(text):
        text = f"{r['channel']}={r['message']}.{r['signal']}{r['rest']}"
    m = _RE.match(text)
    if not m:
        raise UsageError(f"{where}: cannot parse signal map {text!r}; expected "
                         "CHANNEL=[SCALE*]MESSAGE.SIGNAL[*SCALE][+-OFFSET|-mean], "
                         "e.g. x1_ddot=gnss_imu.AccelerationX-9.81")
    scale = 1.0
    if m["pre"]:
        scale *= float(m["pre"])
    if m["post"]:
        scale *= float(m["post"])
    if m["neg"]:
        scale = -scale
    offset: Union[float, str] = 0.0
    if m["mean"]:
        if m["sign"] != "-":
            raise UsageError(f"{where}: {text!r}: the mean can only be subtracted ('-mean')")
        offset = "mean"
    elif m["sign"]:
        offset = float(m["off"] if m["off"] is not None else m["poff"]) * (-1.0 if m["sign"] == "-" else 1.0)
    return SignalMapping(m["channel"], m["message"], m["signal"], scale, offset)


@dataclass
class SignalMap:
    """An ordered set of :class:`SignalMapping`, the DBC its file names (``dbc``, resolved
    relative to the file) and where it came from (``source``, for messages)."""

    mappings: list[SignalMapping]
    dbc: Path | None = None
    source: str = "--map"

    @classmethod
    def from_strings(cls, specs: Iterable[str], where: str = "--map") -> "SignalMap":
        """Build from ``CHANNEL=MESSAGE.SIGNAL...`` strings (command line)."""
        return cls([parse_mapping(s, where) for s in specs], None, where)

    @classmethod
    def from_file(cls, path: str | Path) -> "SignalMap":
        """Read a ``.toml`` or ``.json`` signal-map file (see the module docstring)."""
        p = Path(path)
        if not p.is_file():
            raise InputError(f"{p}: no such signal-map file")
        try:
            if p.suffix.lower() == ".toml":
                data = tomllib.loads(p.read_text(encoding="utf-8"))
            elif p.suffix.lower() == ".json":
                data = json.loads(p.read_text(encoding="utf-8"))
            else:
                raise InputError(f"{p}: unknown signal-map format {p.suffix!r}; expected .toml or .json")
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"{p}: invalid TOML: {exc}") from None
        except json.JSONDecodeError as exc:
            raise InputError(f"{p}:{exc.lineno}: invalid JSON: {exc.msg}") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"{p}: cannot read signal map: {exc}") from None
        if not isinstance(data, dict) or not isinstance(data.get("map"), dict) or not data["map"]:
            raise InputError(f"{p}: expected a 'map' table of channel = \"MESSAGE.SIGNAL...\" entries")
        dbc = data.get("dbc")
        dbc_path = (p.parent / dbc) if isinstance(dbc, str) and dbc else None
        return cls.from_table(data["map"], str(p), dbc_path)

    @classmethod
    def from_table(cls, table: dict[str, object], source: str,
                   dbc: Path | None = None) -> "SignalMap":
        """Build from a parsed ``[map]`` table (a signal-map file's, or a ``--config`` file's):
        ``channel -> "MESSAGE.SIGNAL..."`` or ``channel -> {message, signal[, scale, offset]}``
        (else an :class:`InputError` naming ``FILE: map.CHANNEL``); ``source`` names the file
        in messages; ``dbc`` is the DBC it names."""
        mappings = []
        for channel, spec in table.items():
            where = f"{source}: map.{channel}"
            if isinstance(spec, str):
                mappings.append(parse_mapping(f"{channel}={spec}", where))
            elif isinstance(spec, dict):
                unknown = set(spec) - {"message", "signal", "scale", "offset"}
                if unknown or "message" not in spec or "signal" not in spec:
                    raise InputError(f"{where}: expected keys message, signal[, scale, offset], got "
                                     f"{', '.join(sorted(spec))}")
                try:
                    scale = float(spec.get("scale", 1.0))
                    off = spec.get("offset", 0.0)
                    offset: Union[float, str] = "mean" if off == "mean" else float(off)
                except (TypeError, ValueError):
                    raise InputError(f"{where}: scale and offset must be numbers (offset may be "
                                     f"\"mean\"), got {spec.get('scale')!r}, {spec.get('offset')!r}") from None
                mappings.append(SignalMapping(channel, str(spec["message"]), str(spec["signal"]),
                                              scale, offset))
            else:
                raise InputError(f"{where}: expected a string or a table, got {type(spec).__name__}")
        return cls(mappings, dbc, source)

    @classmethod
    def from_dbc(cls, db: Database, model_name: str) -> "SignalMap":
        """The mapping that suspid's DBC declares for a model (``SuspidChannel`` attributes)."""
        return cls([SignalMapping(ch, m, s) for ch, m, s in channel_signals(db, model_name)],
                   None, f"{getattr(db, 'suspid_path', 'DBC')} (SuspidChannel attributes)")

    def channels(self) -> list[str]:
        """Mapped channels in order."""
        return [m.channel for m in self.mappings]

    def unit_warnings(self, db: Database, model: SuspensionModel) -> list[str]:
        """Warnings for mappings without a scale of a signal the DBC declares in another unit
        than the channel's SI unit (a likely forgotten conversion, ``Height`` in mm)."""
        out = []
        for m in self.mappings:
            if m.scale != 1.0:
                continue
            expected = si_units(model, m.channel)
            try:
                msg = find_message(db, m.message, self.source)
            except (InputError, UsageError):
                continue
            sig = next((x for x in msg.signals if x.name == m.signal), None)
            unit = " ".join(str(getattr(sig, "unit", "") or "").split())
            if not expected or unit in ("", "-") or normalize_unit(unit) in expected:
                continue
            factor, si = TO_SI.get(unit.lower(), (0.0, None))
            # a factor only where it converts to the channel's unit
            hint = (f" (e.g. {m.channel}={m.message}.{m.signal}*{factor:.6g})"
                    if si in expected else "")
            out.append(f"{self.source}: {m}: signal {msg.name}.{m.signal} is in {unit!r} by the "
                       f"DBC but {m.channel} is read in {' or '.join(expected)}, with no scale; "
                       f"give the factor to SI{hint}")
        return out

    def validate(self, db: Database, allowed_channels: Sequence[str]) -> None:
        """Check every mapping against the DBC and the model's channels: an
        :class:`InputError` for an unknown message or signal or a signal of nested multiplexing,
        a :class:`UsageError` for a channel the model does not have, mapped twice, or scale 0."""
        seen: set[str] = set()
        for m in self.mappings:
            where = f"{self.source}: {m}"
            if m.channel not in allowed_channels:
                raise UsageError(f"{where}: channel {m.channel!r} is not a channel of the model; "
                                 f"expected one of {', '.join(allowed_channels)}")
            if m.channel in seen:
                raise UsageError(f"{where}: channel {m.channel!r} is mapped twice")
            seen.add(m.channel)
            msg = find_message(db, m.message, where)
            sig = next((s for s in msg.signals if s.name == m.signal), None)
            if sig is None:
                names = ", ".join(s.name for s in msg.signals)
                raise InputError(f"{where}: message {msg.name} has no signal {m.signal!r}; "
                                 f"expected one of {names}")
            ids = sig.multiplexer_ids or []
            mux = next((s for s in msg.signals if s.name == sig.multiplexer_signal), None) \
                if ids else None
            if mux is not None and mux.multiplexer_ids:
                pages = ", ".join(str(i) for i in ids)
                outer = ", ".join(str(i) for i in mux.multiplexer_ids)
                raise InputError(f"{where}: signal {msg.name}.{m.signal} is sent only when "
                                 f"{mux.name} = {pages}, and {mux.name} only when "
                                 f"{mux.multiplexer_signal} = {outer}: nested multiplexing, "
                                 "which suspid does not decode (one multiplexer per signal)")
            if m.scale == 0:
                raise UsageError(f"{where}: scale must not be 0")


#: factor to SI and SI unit of the units a DBC commonly gives motion signals in (lower case)
TO_SI = {"mm": (1e-3, "m"), "cm": (1e-2, "m"), "mm/s": (1e-3, "m/s"), "cm/s": (1e-2, "m/s"),
         "mm/s^2": (1e-3, "m/s^2"), "g": (9.80665, "m/s^2"), "mg": (9.80665e-3, "m/s^2"),
         "deg": (math.pi / 180, "rad"), "°": (math.pi / 180, "rad"),
         "deg/s": (math.pi / 180, "rad/s"), "°/s": (math.pi / 180, "rad/s"),
         "km/h": (1 / 3.6, "m/s"), "km": (1e3, "m")}

SignalMapLike = Union[SignalMap, str, Path, Sequence[str], None]


def as_signal_map(spec: SignalMapLike) -> SignalMap | None:
    """Normalise what callers pass: a SignalMap, a config path, or ``--map`` strings."""
    if spec is None or isinstance(spec, SignalMap):
        return spec
    if isinstance(spec, Path):
        return SignalMap.from_file(spec)
    if isinstance(spec, str):
        if "=" in spec:
            return SignalMap.from_strings([spec])
        return SignalMap.from_file(spec)
    specs = list(spec)
    if not specs:
        return None
    return SignalMap.from_strings(specs)


def merge_maps(maps: Iterable[SignalMap | None]) -> SignalMap | None:
    """Concatenate maps (e.g. a ``--config`` file's ``[map]`` and ``--map`` options); later
    entries win."""
    result: dict[str, SignalMapping] = {}
    dbc: Path | None = None
    sources = []
    for m in maps:
        if m is None:
            continue
        sources.append(m.source)
        dbc = m.dbc or dbc
        for e in m.mappings:
            result.pop(e.channel, None)
            result[e.channel] = e
    if not sources:
        return None
    return SignalMap(list(result.values()), dbc, " + ".join(sources))

