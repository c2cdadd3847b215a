"""The ``--config FILE`` of the subcommands: one TOML file with the tuning the options leave out.

:data:`SCHEMA` lists every table and key (``docs/configuration.md`` is the same table). A
command reads the tables it uses (:data:`TABLES`) and ignores the others; an unknown table or
key, or a bad value, is one :class:`~suspid.errors.InputError` line naming the file,
``table.key``, expected and got. ``[map]`` is :mod:`suspid.can.signal_map`'s format.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from suspid.can.signal_map import SignalMap
from suspid.errors import InputError

__all__ = ["Key", "SCHEMA", "TABLES", "Config", "load_config"]


@dataclass(frozen=True)
class Key:
    """One configuration key: its type, SI unit, documented default, meaning and range.

    ``type`` is ``int``, ``float``, ``bool``, ``str`` (one of ``choices`` when given), ``names``
    (a list of strings), ``address`` (a string or integer; with ``lo``/``hi`` an integer in that
    range, ``"0x47"`` too) or ``x0`` (``"estimate"``, ``"rest"`` or a list of numbers).
    """

    type: str
    unit: str
    default: str
    meaning: str
    lo: float | None = None
    hi: float | None = None
    open_lo: bool = False
    open_hi: bool = False
    choices: tuple[str, ...] = ()

    def expected(self) -> str:
        """What a valid value is, in words (for messages)."""
        if self.choices:
            return "one of " + ", ".join(repr(c) for c in self.choices)
        what = {"int": "an integer", "float": "a number", "bool": "true or false",
                "str": "a string", "names": "a list of parameter names",
                "address": "an address (string or integer)",
                "x0": "\"estimate\", \"rest\" or a list of finite numbers"}[self.type]
        parts = []
        if self.lo is not None:
            parts.append(f"{'>' if self.open_lo else '>='} {self.lo:g}")
        if self.hi is not None:
            parts.append(f"{'<' if self.open_hi else '<='} {self.hi:g}")
        return what + (" " + " and ".join(parts) if parts else "")

    def check(self, value: Any) -> Any:
        """``value`` converted to the key's Python type, or ``ValueError`` if it does not fit."""
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        if self.type == "bool" and isinstance(value, bool):
            return value
        if self.type == "int" and number and isinstance(value, int):
            self._check_range(value)
            return value
        if self.type == "float" and number and math.isfinite(float(value)):
            self._check_range(float(value))
            return float(value)
        if self.type == "str" and isinstance(value, str) and (not self.choices or value in self.choices):
            return value
        if self.type == "names" and isinstance(value, list) and all(isinstance(v, str) for v in value):
            return tuple(v.strip() for v in value)
        if self.type == "x0" and value in ("estimate", "rest"):
            return value
        if self.type == "x0" and isinstance(value, list) and value and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value):
            return ",".join(repr(float(v)) for v in value)
        if self.type == "address" and isinstance(value, (str, int)) and not isinstance(value, bool):
            if self.hi is not None:   # a numeric address: 0x47, "71", 71
                self._check_range(value if isinstance(value, int) else int(value.strip(), 0))
            return str(value)
        raise ValueError

    def _check_range(self, v: float) -> None:
        if self.lo is not None and (v <= self.lo if self.open_lo else v < self.lo):
            raise ValueError
        if self.hi is not None and (v >= self.hi if self.open_hi else v > self.hi):
            raise ValueError


def _f(unit: str, default: str, meaning: str, lo: float | None = None, hi: float | None = None,
       open_lo: bool = False, open_hi: bool = False) -> Key:
    return Key("float", unit, default, meaning, lo, hi, open_lo, open_hi)


def _i(default: str, meaning: str, lo: float | None = None, unit: str = "") -> Key:
    return Key("int", unit, default, meaning, lo)


def _b(default: str, meaning: str) -> Key:
    return Key("bool", "", default, meaning)


def _s(default: str, meaning: str, choices: tuple[str, ...] = ()) -> Key:
    return Key("str", "", default, meaning, choices=choices)


#: every table and key a configuration file may hold
SCHEMA: dict[str, dict[str, Key]] = {
    "can": {
        "dbc": _s("the bundled dbc/suspension.dbc", "DBC of CAN-log input, relative to the configuration "
                  "file; --dbc wins"),
        "channel": Key("address", "", "every channel (warned when the sensor's messages are on several)",
                       "decode only this bus channel of a log that records several, as the file names it: 1, "
                       "2, ... for ASC/BLF channels, TRC buses and MDF4 BusChannel, can0/can1 for candump; "
                       "other channels' frames are counted (frames.other_channel)"),
        "j1939_source": Key("address", "", "the first sender of each PGN", "a J1939 DBC: decode its "
                            "parameter groups from this source address only (0..253, e.g. \"0x00\" the "
                            "engine)", lo=0, hi=253),
    },
    "fit": {
        "restarts": _i("6 (diagnose: 3)", "Nelder-Mead restarts from the best vertex", 0),
        "multistart": _i("4", "further starts on a suspicious local minimum", 0),
        "polish": _b("true", "Levenberg-Marquardt polish after Nelder-Mead; false: pure Nelder-Mead to full "
                     "tolerance"),
        "data_start": _b("true", "also start from the data's own estimate (false: only from --init and the "
                         "model's defaults); identify and fleet"),
        "x0": Key("x0", "SI", "\"estimate\"", "initial state: \"estimate\" (variable projection), \"rest\", "
                  "or the state [q..., q_dot...] as a list of numbers"),
    },
    "window": {
        "decimate": _i("20 samples per period of the fastest mode", "fit every N-th sample", 1),
        "budget": _i("40 per free parameter", "Nelder-Mead evaluations of a warm-started window", 10),
        "first_budget": _i("250 per free parameter", "evaluations of the first, cold-started window", 10),
        "sigma_floor": _f("", "0.005", "relative standard error added in quadrature to each window's", 0.0,
                          1.0),
        "min_deflection": _f("m", "0.0005", "skip windows whose RMS suspension deflection is below this",
                             0.0),
        "min_snr": _f("", "3", "skip windows whose deflection is below this multiple of the noise floor "
                      "estimated from the data", 0.0),
        "road_fusion_hz": _f("Hz", "1.5 x the highest natural frequency", "road fed to each fit: measured r "
                             "below, integral of measured r_dot above; 0: r as measured", 0.0),
        "road_lowpass_hz": _f("Hz", "0 (off)", "zero-phase low-pass (-6 dB) of the road fed to each fit",
                              0.0),
        "drift": Key("names", "", "every free damper and spring of the struts", "free parameters fitted with "
                     "a linear drift over each window, so their estimate refers to the window's end; []: "
                     "every parameter constant"),
        "drift_chunk_s": _f("s", "0.2", "chunk over which a drifting parameter is held constant in the drift "
                            "fit", 0.0, open_lo=True),
        "drift_rate_sd": _f("1/s", "0.005", "standard deviation (relative) of the prior on each window's "
                            "drift rate, centred on the recent estimates' rate; 0: no prior", 0.0),
        "offset": _s("\"remove\"", "a constant offset in a road or position channel found on the first "
                     "fitted window: remove subtracts it, keep fits the data as they are (either way warned)",
                     ("remove", "keep")),
    },
    "alert": {
        "confidence": _f("", "0.99", "one-sided confidence of the alert bound", 0.5, 1.0, open_lo=True,
                         open_hi=True),
        "persistence_s": _f("s", "one window step", "data time a drop must persist before alerting (monitor)",
                            0.0),
        "hysteresis": _f("", "0.05", "clear an alert only above (1 - drop + this) x nominal (monitor)", 0.0,
                         1.0, open_hi=True),
        "forecast_horizon_s": _f("s", "60", "announce a predicted limit crossing due within this much data "
                                 "time (monitor, compare)", 0.0, open_lo=True),
        "drives": _i("1", "consecutive drives the drop must hold in before an alert (fleet)", 1),
        "horizon_days": _f("d", "365", "report limit-crossing forecasts up to this many days after the "
                           "latest drive (fleet)", 0.0, open_lo=True),
    },
    "ekf": {
        "params": Key("names", "", "every free damper and spring", "parameters in the EKF's augmented state"),
        "q": _f("1/sqrt(s)", "0.005", "parameter random walk (relative)", 0.0, open_lo=True),
        "decimate": _i("250 Hz or less", "run the EKF on every N-th sample", 1),
    },
    "live": {
        "bitrate": _i("the interface's", "bitrate of --interface", 1, unit="bit/s"),
        "idle_timeout_s": _f("s", "5", "stop when no frame arrived for this long (0: never)", 0.0),
        "time_source": _s("tick on a live bus, timestamp for a log", "data time from frame timestamps or "
                          "from the sensor node's SN_Sync ticks", ("timestamp", "tick")),
        "rx_buffer_s": _f("s", "10", "frames the receiver thread may hold while the fits lag, in seconds of "
                          "data at the DBC's frame rate", 0.0, open_lo=True),
        "slcan_timestamps": _b("false", "--interface slcan: time frames by the adapter's clock (Lawicel Z1) "
                               "instead of the host's arrival time"),
        "alert_frames": _b("true", "send SUSPID_Alert frames on the live bus"),
        "alert_interface": _s("the live bus", "send SUSPID_Alert frames on this bus instead"),
        "alert_channel": _s("", "channel of alert_interface"),
        "duration_s": _f("s", "none", "stop after this much wall time", 0.0, open_lo=True),
    },
    "output_only": {
        "accel_channel": _s("x1_ddot / x_ddot", "channel of the body acceleration"),
        "method": _s("\"carma\"", "body-mode estimator: carma (parametric spectral fit) or ar (AR(6) poles)",
                     ("carma", "ar")),
    },
    "monitor": {
        "summary": _b("true", "print the closing summary line"),
    },
    "fleet": {
        "progress": _b("true", "progress bar on stderr (one line per tenth of the work when stderr is not a "
                       "terminal)"),
    },
    "simulate": {
        "height_m": _f("m", "0.1", "curb or bump height (negative: a pothole)"),
        "length_m": _f("m", "3", "bump length", 0.0, open_lo=True),
        "road_class": _s("\"C\"", "ISO 8608 road class of the random scenario",
                         ("A", "B", "C", "D", "E", "F", "G", "H")),
        "t0_s": _f("s", "0.5", "time the wheel reaches the curb or bump", 0.0),
    },
    "node": {
        "open_timeout_s": _f("s", "60", "--channel pty: wait this long for a host to open the adapter", 0.0,
                             open_lo=True),
        "linger_s": _f("s", "3", "after the scenario, wait at most this long for the host to close the "
                       "adapter", 0.0),
    },
    "doe": {
        "single_stage": _b("false", "fit the whole record at once (no horizon continuation; ablation)"),
        "restarts": _i("0 (6 with single_stage)", "Nelder-Mead restarts of the final stage", 0),
        "data_start": _b("true", "also start from the data-driven estimate, keeping the lower-cost answer "
                         "(false: --init-scale x the truth only)"),
        "progress": _b("false", "draw the progress bar on stderr even when it is not a terminal"),
    },
    "map": {},   # channel = "MESSAGE.SIGNAL..." (suspid.can.signal_map)
}


#: the tables each subcommand reads (the others in a file are checked and ignored)
TABLES: dict[str, tuple[str, ...]] = {
    "identify": ("can", "map", "fit"),
    "diagnose": ("can", "map", "fit"),
    "fleet": ("can", "map", "fit", "alert", "fleet"),
    "monitor": ("can", "map", "window", "alert", "ekf", "live", "output_only", "monitor"),
    "compare": ("can", "map", "window", "alert", "ekf"),
    "simulate": ("simulate",),
    "node": ("node",),
    "doe": ("doe",),
}


@dataclass
class Config:
    """A checked configuration file (``path`` ``None``: every default): ``tables`` holds the
    keys it sets (``table -> {key: value}``), ``signal_map`` its ``[map]`` table."""

    path: Path | None = None
    tables: dict[str, dict[str, Any]] | None = None
    signal_map: SignalMap | None = None

    def table(self, name: str) -> dict[str, Any]:
        """The keys ``[name]`` sets (empty when absent)."""
        return dict((self.tables or {}).get(name, {}))

    def get(self, table: str, key: str, default: Any = None) -> Any:
        """``table.key`` if the file sets it, else ``default``."""
        return (self.tables or {}).get(table, {}).get(key, default)

    def fields(self, table: str, names: Mapping[str, str]) -> dict[str, Any]:
        """The keys of ``table`` the file sets, renamed by ``names`` (key -> field)."""
        return {names.get(k, k): v for k, v in self.table(table).items()}


def _got(value: Any) -> str:
    kind = {bool: "boolean", int: "integer", float: "float", str: "string", list: "array",
            dict: "table"}.get(type(value), type(value).__name__)
    return f"{value!r} ({kind})"


def load_config(path: str | Path | None) -> Config:
    """Read and check the ``--config`` file (``None``: an empty :class:`Config`).

    Raises
    ------
    InputError
        Unreadable, not TOML, an unknown table or key, or a bad value (one line naming the
        file, ``table.key``, expected and got).
    """
    if path is None:
        return Config()
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such configuration file" if not p.is_dir()
                         else f"{p}: is a directory, expected a configuration file (TOML)")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{p}: invalid TOML: {exc}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{p}: cannot read the configuration: {exc}") from None
    tables: dict[str, dict[str, Any]] = {}
    for name, table in data.items():
        if name not in SCHEMA:
            raise InputError(f"{p}: unknown table [{name}]; expected one of "
                             + ", ".join(f"[{t}]" for t in SCHEMA))
        if not isinstance(table, dict):
            raise InputError(f"{p}: {name}: expected a table [{name}], got {_got(table)}")
        if name == "map":
            continue
        keys = SCHEMA[name]
        out: dict[str, Any] = {}
        for key, value in table.items():
            spec = keys.get(key)
            if spec is None:
                raise InputError(f"{p}: unknown key {name}.{key}; expected one of "
                                 + ", ".join(keys))
            try:
                out[key] = spec.check(value)
            except ValueError:
                unit = f" ({spec.unit})" if spec.unit else ""
                raise InputError(f"{p}: {name}.{key}: expected {spec.expected()}{unit}, "
                                 f"got {_got(value)}") from None
        tables[name] = out
    dbc_path = (p.parent / tables["can"]["dbc"]) if tables.get("can", {}).get("dbc") else None
    if dbc_path is not None:
        tables["can"]["dbc"] = str(dbc_path)
    smap = SignalMap.from_table(data["map"], str(p), dbc_path) if data.get("map") else None
    return Config(p, tables, smap)
