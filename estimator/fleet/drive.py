"""One drive: identify one log exactly as ``suspid identify`` does (the Dask task).

A worker imports this module once and parses the DBC once (:func:`cached_database`); the
calls are ``identify``'s own, so the results are equal to the last digit.
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from cantools.database import Database

from estimator.decode.listener import DecodeListener
from estimator.decode.replay import feed_log
from estimator.identify.inputs import read_input
from estimator.identify import IdentResult, OutputErrorProblem, Parameters
from estimator.identify.record import identify_record
from estimator.identify.roadfree import fit_road_unknown, resolve_road
from suspid import __version__
from suspid.can.dbc import default_dbc_path, load_dbc
from suspid.can.logs import FORMATS, ReadStats, first_timestamp
from suspid.can.signal_map import SignalMap, merge_maps
from suspid.errors import InputError, SuspidError
from suspid.io.csvio import AUX_CHANNELS, Measurement
from suspid.models import SuspensionModel, get_model

#: suffixes read as CAN logs (python-can formats), and as measurement CSVs
CAN_SUFFIXES: tuple[str, ...] = tuple(FORMATS)
CSV_SUFFIXES: tuple[str, ...] = (".csv",)
#: every suffix a drive log may have
DRIVE_SUFFIXES: tuple[str, ...] = CAN_SUFFIXES + CSV_SUFFIXES
_HASH_CHUNK = 1 << 20


@dataclass(frozen=True)
class IdentifySettings:
    """The options of ``suspid identify`` that decide a drive's result (``fix``/``init`` in SI;
    ``road`` ``None`` chooses per drive as ``identify`` does).
    """

    model: str
    fix: dict[str, float] = field(default_factory=dict)
    init: dict[str, float] = field(default_factory=dict)
    cost: str = "sse"
    x0: Any = "estimate"
    restarts: int = 6
    maxfev: int | None = None
    multistart: int = 4
    polish: bool = True
    data_start: bool = True
    dbc: str | None = None
    signal_map: SignalMap | None = None
    can_channel: str | None = None
    offset: str = "remove"
    j1939_source: str | None = None
    road: str | None = None

    def parameters(self) -> Parameters:
        """The identifier's parameters (raises :class:`UsageError` for unknown names)."""
        return Parameters.for_model(get_model(self.model), fix=self.fix, init=self.init)

    def key(self) -> str:
        """A stable text key of the settings, the DBC's content hash and the suspid version."""
        d = asdict(self)
        dbc = Path(self.dbc) if self.dbc is not None else default_dbc_path()
        try:
            d["dbc_sha256"] = file_digest(dbc)
        except OSError:
            d["dbc_sha256"] = None
        d["suspid"] = __version__
        for k in ("can_channel", "j1939_source"):
            if d[k] is None:
                del d[k]
        d["road"] = self.road if self.road is not None else "auto"
        d["x0"] = self.x0 if isinstance(self.x0, str) else [float(v) for v in self.x0]
        d["signal_map"] = (None if self.signal_map is None else
                           [str(m) for m in self.signal_map.mappings])
        return json.dumps(d, sort_keys=True)


def file_digest(path: str | Path) -> str:
    """SHA-256 of a file's bytes (hex): a drive's identity in the history (OSError if unreadable)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(_HASH_CHUNK), b""):
            h.update(chunk)
    return h.hexdigest()


@lru_cache(maxsize=16)
def _database(path: str, mtime_ns: int, size: int) -> Database:
    return load_dbc(path)


def cached_database(path: str | None) -> Database:
    """The DBC at ``path`` (default: suspid's), parsed once per process and file version."""
    p = Path(path) if path is not None else default_dbc_path()
    try:
        st = p.stat()
    except OSError:
        return load_dbc(p)          # raises the one-line "no such DBC file" error
    return _database(str(p), st.st_mtime_ns, st.st_size)


def load_drive(path: str | Path, model: SuspensionModel, settings: IdentifySettings
               ) -> tuple[Measurement, dict[str, Any] | None]:
    """Read a drive log as ``suspid identify --input PATH`` does: the measurement and CAN frame counts."""
    db = cached_database(settings.dbc)
    return read_input(path, model, db, with_declared_channels(settings.signal_map, db, model),
                      channel=settings.can_channel, j1939_source=settings.j1939_source)


def with_declared_channels(signal_map: SignalMap | None, db: Database,
                           model: SuspensionModel) -> SignalMap | None:
    """A map of distance channels alone completed with the channels the DBC declares for the model."""
    if signal_map is None or any(c not in AUX_CHANNELS for c in signal_map.channels()):
        return signal_map
    declared = SignalMap.from_dbc(db, model.name)
    return merge_maps([declared, signal_map]) if declared.mappings else signal_map


def drive_distance(meas: Measurement) -> dict[str, Any]:
    """The distance a drive covered: ``odometer_m`` (first reading), ``distance_m`` (odometer, else
    integrated speed; m) and ``distance_source``; an odometer running backwards gives none.
    """
    out: dict[str, Any] = {"odometer_m": None, "distance_m": None, "distance_source": None}
    odo = meas.aux.get("odometer")
    if odo is not None and np.isfinite(odo).any():
        vals = odo[np.isfinite(odo)]
        if float(vals[-1]) >= float(vals[0]):
            out.update(odometer_m=float(vals[0]), distance_m=float(vals[-1] - vals[0]),
                       distance_source="odometer")
            return out
    speed = meas.aux.get("speed")
    if speed is not None and np.count_nonzero(np.isfinite(speed)) >= 2:
        ok = np.isfinite(speed)
        out.update(distance_m=float(np.trapezoid(np.abs(speed[ok]), meas.t[ok])),
                   distance_source="speed")
    return out


def distance_by_timestamp(path: str | Path, model: SuspensionModel, settings: IdentifySettings
                          ) -> Measurement | None:
    """The distance channels of a CAN log decoded on the frames' timestamps (a J1939 odometer has no
    sensor tick); ``None`` without a mapped or accepted distance channel.
    """
    smap = settings.signal_map
    if smap is None:
        return None
    aux = SignalMap([m for m in smap.mappings if m.channel in AUX_CHANNELS], smap.dbc,
                    smap.source)
    if not aux.mappings:
        return None
    listener = DecodeListener(model, cached_database(settings.dbc), aux, growable=True,
                              time_source="timestamp", j1939_source=settings.j1939_source)
    feed_log(listener, path, ReadStats(), channel=settings.can_channel)
    if not any(s.n for s in listener.buffer.sources.values()):
        return None
    al = listener.aligned()
    return Measurement(t=al.t, aux={k: v for k, v in al.values.items() if k in AUX_CHANNELS})


def one_line(text: object) -> str:
    """``text`` on one line (runs of whitespace become one space)."""
    return " ".join(str(text).split())


def identify_measurement(model: SuspensionModel, meas: Measurement,
                         settings: IdentifySettings) -> IdentResult:
    """Identify one record as ``suspid identify --road ...`` does (the road mode resolved first)."""
    road, meas, road_warnings = resolve_road(model, meas, settings.road)
    if road == "unknown":
        result = fit_road_unknown(model, meas, settings.parameters())
    else:
        problem = OutputErrorProblem(model, meas, cost=settings.cost,
                                     x0=(settings.x0 if isinstance(settings.x0, str)
                                         else np.asarray(settings.x0, dtype=float)))
        result = identify_record(problem, settings.parameters(), restarts=settings.restarts,
                                 maxfev=settings.maxfev, polish=settings.polish,
                                 multistart=settings.multistart, data_start=settings.data_start,
                                 keep_init=bool(settings.init) or not settings.data_start,
                                 offset=settings.offset)[0]
        result.road = road
    result.warnings[:0] = road_warnings
    return result


def determined(result: dict[str, Any]) -> list[str]:
    """The free parameters a drive's result (an identify JSON object) gives a finite value for."""
    if not result.get("success"):
        return []
    fixed = set(result.get("fixed", []))
    und = set(result.get("undetermined") or [])
    se = result.get("stderr") or {}
    return [k for k in result.get("params", {}) if k not in fixed and k not in und
            and se.get(k) is not None and math.isfinite(float(se[k]))]


def classify(result: dict[str, Any] | None) -> tuple[str, str | None]:
    """A read drive's status: ``("ok", None)`` or ``("unidentified", one-line reason)``."""
    if result is None:
        return "unidentified", "no identification result"
    if determined(result):
        return "ok", None
    notes = [w for w in result.get("warnings", [])
             if "identifiab" in w or "cannot form" in w or w.startswith("road unknown: no ")]
    why = "success false" if not result.get("success") else "no free parameter determined"
    return "unidentified", one_line(f"not identified ({why})"
                                    + (f": {'; '.join(notes)}" if notes else ""))


def identify_drive(path: str, vehicle: str, settings: IdentifySettings,
                   digest: str | None = None) -> dict[str, Any]:
    """Identify one drive; never raises for a bad log (the Dask task).

    Returns ``path``, ``vehicle``, ``sha256``, ``size``, ``t`` (epoch s), the distance, ``status``
    (``"ok"``, ``"unidentified"``, ``"failed"``), ``error`` and ``result`` (identify's JSON).
    """
    out: dict[str, Any] = {"path": path, "vehicle": vehicle, "sha256": digest, "size": None,
                           "t": None, "status": "failed", "error": None, "result": None,
                           "odometer_m": None, "distance_m": None, "distance_source": None}
    try:
        out["size"] = Path(path).stat().st_size
        if digest is None:
            out["sha256"] = file_digest(path)
        model = get_model(settings.model)
        meas, frames = load_drive(path, model, settings)
        # the drive's time is the log's own first timestamp (epoch s), not the data time
        stamp = first_timestamp(path) if frames is not None else None
        t0 = stamp if stamp is not None else (float(meas.t[0]) if meas.t.size else math.nan)
        if not math.isfinite(t0):
            raise InputError(f"{path}: no sample time")
        out["t"] = t0
        dist = drive_distance(meas)
        if (dist["distance_source"] is None and frames is not None
                and frames.get("time_base") == "tick"):
            again = distance_by_timestamp(path, model, settings)
            if again is not None:
                dist = drive_distance(again)
        out.update(dist)
        result = identify_measurement(model, meas, settings)
        if frames is not None:
            result.frames = frames
        out["result"] = result.to_json()
        out["status"], why = classify(out["result"])
        out["error"] = None if why is None else f"{path}: {why}"
    except SuspidError as exc:
        out["error"] = one_line(exc)
    except OSError as exc:
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else f"{path}: "
        out["error"] = one_line(f"{where}{exc.strerror or exc}")
    except Exception as exc:  # noqa: BLE001 - a bad log must never stop the batch
        out["error"] = one_line(f"{path}: {type(exc).__name__}: {exc}")
    return out
