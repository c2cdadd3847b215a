"""Per-vehicle history, trends, alerts, forecasts and risk ranking from drive records.

Only ``ok`` drives and the parameters they determined count; dampers and springs are monitored,
masses and inertias are the load. Alerts follow the monitor's rule with each drive as one
estimate. See ``docs/fleet.md``.
"""
from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Any, Iterable

import numpy as np

from estimator.alerts.engine import AlertConfig, AlertEngine
from estimator.fleet.drive import determined
from estimator.alerts.forecast import Trend
from estimator.fleet.trend import (DAY_S, KM, Forecast, forecast_crossing, limit_crossing,
                                   robust_trend, trend_json)
from suspid.models import get_model


#: 2000-01-01 00:00 UTC (epoch s): a drive starting before it carries no epoch time
EPOCH_FLOOR = 946684800.0


def time_warnings(vehicle: str, times: list[float]) -> list[str]:
    """What makes a vehicle's drive times (epoch s) unfit for a trend, one line each."""
    out: list[str] = []
    early = [t for t in times if t < EPOCH_FLOOR]
    if early:
        out.append(f"vehicle {vehicle}: {len(early)} of {len(times)} drives start before "
                   f"2000-01-01 (first sample t = {min(early):.6g} s): their logs carry the "
                   "time since the record's start, not the epoch time; the trend and "
                   "forecast need each drive's date (log with a real-time clock, or a CSV "
                   "whose t is epoch seconds)")
    shared = sum(c for c in Counter(times).values() if c > 1)
    if shared:
        out.append(f"vehicle {vehicle}: {shared} of {len(times)} drives share their drive "
                   "time with another drive; the trend tells drives apart by time only")
    return out


@dataclass
class VehicleSummary:
    """One vehicle's drives and what they say."""

    vehicle: str
    model: str
    drives: list[dict[str, Any]]
    failed: int
    monitored: list[str]
    nominal: dict[str, float]
    limits: dict[str, float]
    trends: dict[str, Trend | None]
    forecasts: dict[str, Forecast]
    alerts: list[dict[str, Any]]
    risk: str = "ok"
    rank: int = 0
    warnings: list[str] = field(default_factory=list)
    offsets: dict[str, dict[str, Any]] = field(default_factory=dict)
    unidentified: list[dict[str, Any]] = field(default_factory=list)
    loads: list[str] = field(default_factory=list)
    #: ``"odometer"``, ``"speed"`` (cumulative logged distance) or ``None``
    distance_source: str | None = None
    #: each read drive's position on the vehicle's distance scale (m), by ``(path, t)``
    positions: dict[tuple[str, float], float] = field(default_factory=dict)
    trends_km: dict[str, Trend | None] = field(default_factory=dict)

    def position(self, rec: dict[str, Any]) -> float | None:
        """A drive's position on the distance scale (m), ``None`` when unknown."""
        return self.positions.get((rec["path"], float(rec["t"])))

    def latest_position(self) -> float | None:
        """The latest ``ok`` drive's position (m), else the largest known one."""
        last = self.latest
        pos = self.position(last) if last is not None else None
        return pos if pos is not None else max(self.positions.values(), default=None)

    @property
    def latest(self) -> dict[str, Any] | None:
        return self.drives[-1] if self.drives else None

    def series(self, name: str) -> list[dict[str, Any]]:
        """The ``ok`` drives that determine ``name`` (oldest first): its trend's points."""
        return [r for r in self.drives if name in determined(r["result"])]

    def latest_value(self, name: str) -> float | None:
        """``name``'s estimate in the latest drive that determines it (SI)."""
        ser = self.series(name)
        return float(ser[-1]["result"]["params"][name]) if ser else None

    def roads(self) -> dict[str, int]:
        """Road mode -> number of ``ok`` drives fitted in it."""
        return dict(Counter(str(r["result"].get("road", "measured")) for r in self.drives))

    def sort_key(self) -> tuple[int, float, float, str]:
        """Most at risk first: alerts, the earliest forecast crossing, the smallest margin."""
        level = {"alert": 0, "forecast": 1, "ok": 2, "no data": 3}[self.risk]
        first = min((f.crossing_t for f in self.forecasts.values()), default=math.inf)
        return level, first, self.margin(), self.vehicle

    def margin(self) -> float:
        """Smallest ``(latest - limit) / (nominal - limit)`` over monitored parameters."""
        if self.latest is None:
            return math.inf
        out = math.inf
        for k in self.monitored:
            v = self.latest_value(k)
            if v is not None and self.nominal[k] > self.limits[k]:
                out = min(out, (v - self.limits[k]) / (self.nominal[k] - self.limits[k]))
        return out

    def to_json(self) -> dict[str, Any]:
        """The contract's vehicle object, then the rest."""
        last = self.latest
        res = last["result"] if last else {}
        known = set(determined(res)) | set(res.get("fixed", [])) if last else set()
        pos = self.latest_position()
        return {
            "vehicle": self.vehicle,
            "drives": len(self.drives),
            "latest": ({k: v for k, v in res["params"].items() if k in known} if last
                       else None),
            "trend": {k: trend_json(tr) for k, tr in self.trends.items() if tr is not None},
            "alerts": [a["parameter"] for a in self.alerts],
            "forecast": {k: f.to_json() for k, f in self.forecasts.items()},
            "rank": self.rank,
            "risk": self.risk,
            "model": self.model,
            "failed": self.failed,
            "latest_t": last["t"] if last else None,
            "latest_stderr": dict(last["result"].get("stderr", {})) if last else None,
            "limits": dict(self.limits),
            "nominal": dict(self.nominal),
            "alert_details": self.alerts,
            "margin": self.margin() if math.isfinite(self.margin()) else None,
            "warnings": list(self.warnings),
            "sensor_offsets": {k: dict(v) for k, v in self.offsets.items()},
            "latest_undetermined": ([k for k in res["params"] if k not in known] if last
                                    else []),
            "unidentified": [{"path": r["path"], "t": r.get("t"), "error": r.get("error")}
                             for r in self.unidentified],
            "roads": self.roads(),
            "loads": {k: [{"t": float(r["t"]), "value": float(r["result"]["params"][k]),
                           "stderr": r["result"]["stderr"].get(k)} for r in self.series(k)]
                      for k in self.loads},
            # the latest drive's position and the drives with one
            "distance": {"source": self.distance_source,
                         "odometer_km": None if pos is None else round(pos / KM, 3),
                         "drives": len(self.positions)},
            "trend_km": {k: trend_json(tr, per=KM, unit="km")
                         for k, tr in self.trends_km.items() if tr is not None},
        }


def sensor_offsets(records: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """The constant offsets ``identify`` found in a vehicle's drives, by column (a calibration when
    found drive after drive): ``kind``, ``drives`` of ``of``, ``median``/``min``/``max``, ``latest_t``.
    """
    found: dict[str, list[tuple[float, float, str, bool]]] = {}
    for r in records:
        off = (r.get("result") or {}).get("offset")
        if not off:
            continue
        for col, d in off.get("values", {}).items():
            found.setdefault(col, []).append((float(r["t"]), float(d), str(off.get("kind")),
                                              bool(off.get("removed"))))
    out: dict[str, dict[str, Any]] = {}
    for col, items in sorted(found.items()):
        vals = [d for _, d, _, _ in items]
        last = max(items)
        out[col] = {"kind": last[2], "drives": len(items), "of": len(records),
                    "median": float(np.median(vals)), "min": min(vals), "max": max(vals),
                    "latest_t": last[0], "removed": last[3]}
    return out


def drive_positions(records: list[dict[str, Any]]
                    ) -> tuple[str | None, dict[tuple[str, float], float]]:
    """Each read drive's position on its vehicle's distance scale: ``(source, {(path, t): m})``; with
    the speed alone, the distance logged before the drive.
    """
    timed = sorted((r for r in records if r.get("t") is not None),
                   key=lambda r: (float(r["t"]), r["path"]))
    if any(r.get("odometer_m") is not None for r in timed):
        return "odometer", {(r["path"], float(r["t"])): float(r["odometer_m"]) for r in timed
                            if r.get("odometer_m") is not None}
    if not any(r.get("distance_m") is not None for r in timed):
        return None, {}
    out: dict[tuple[str, float], float] = {}
    done = 0.0
    for r in timed:
        out[(r["path"], float(r["t"]))] = done
        done += float(r.get("distance_m") or 0.0)
    return "speed", out


def _model_of(rec: dict[str, Any]) -> str:
    return str(rec.get("model") or rec["result"]["model"])


#: parameter kinds that wear (monitored), and those that are the drive's load
WEAR_KINDS = ("damping", "stiffness")
LOAD_KINDS = ("mass", "inertia")


def summarize_vehicle(vehicle: str, records: list[dict[str, Any]], rule: AlertConfig
                      ) -> VehicleSummary:
    """History, trends, alerts and forecasts of one vehicle from its drive records (any status)."""
    def when(r: dict[str, Any]) -> tuple[float, str]:
        return (float(r["t"]) if r.get("t") is not None else math.inf, r["path"])

    ok = sorted((r for r in records if r["status"] == "ok" and r.get("result")), key=when)
    failed = sum(1 for r in records if r["status"] == "failed")
    unidentified = sorted((r for r in records if r["status"] == "unidentified"), key=when)
    if not ok:
        return VehicleSummary(vehicle, "", [], failed, [], {}, {}, {}, {}, [], "no data",
                              unidentified=unidentified)
    model = _model_of(ok[-1])
    # a history may mix models: follow the latest drive's
    ok = [r for r in ok if _model_of(r) == model]
    spec = get_model(model).spec
    fixed = set(ok[-1]["result"].get("fixed", []))
    seen = {k for r in ok for k in determined(r["result"])}
    free = [k for k in ok[-1]["result"]["params"] if k not in fixed and k in seen]
    monitored = [k for k in free if spec(k).kind in WEAR_KINDS]
    loads = [k for k in free if spec(k).kind in LOAD_KINDS]
    nominal = {k: rule.nominal_of(model, k) for k in monitored}
    cfg = replace(rule, nominal=nominal)
    limits = {k: cfg.limit(k) for k in monitored}
    engine = AlertEngine(cfg, model, units={k: spec(k).unit for k in monitored})
    for r in ok:
        res = r["result"]
        det = [k for k in determined(res) if k in nominal]
        engine.update(float(r["t"]), {k: float(res["params"][k]) for k in det},
                      {k: float(res["stderr"][k]) for k in det})
    alerts = []
    for k in monitored:
        if engine.states[k].active:
            ev = next(e for e in reversed(engine.emitted) if e.parameter == k and e.kind == "alert")
            alerts.append({"parameter": k, "value": ev.value, "stderr": ev.stderr,
                           "bound": ev.bound, "limit": ev.limit, "nominal": ev.nominal,
                           "since_t": ev.onset, "t": ev.t, "severity": ev.severity,
                           "message": ev.message})
    alerted = {a["parameter"] for a in alerts}
    t_latest = float(ok[-1]["t"])
    trends: dict[str, Trend | None] = {}
    forecasts: dict[str, Forecast] = {}
    summary = VehicleSummary(vehicle, model, ok, failed, monitored, nominal, limits, trends,
                             forecasts, alerts, warnings=time_warnings(
                                 vehicle, [float(r["t"]) for r in ok]),
                             offsets=sensor_offsets(ok), unidentified=unidentified, loads=loads)
    summary.distance_source, summary.positions = drive_positions(ok + unidentified)
    x_latest = summary.latest_position()
    for k in monitored:
        ser = summary.series(k)
        t = np.array([float(r["t"]) for r in ser])
        v = np.array([float(r["result"]["params"][k]) for r in ser])
        s = np.array([float(r["result"]["stderr"][k]) for r in ser])
        tr = robust_trend(t, v, s)
        trends[k] = tr
        trk = None
        if summary.distance_source is not None:
            x = np.array([math.nan if summary.position(r) is None else summary.position(r)
                          for r in ser], dtype=float)
            trk = summary.trends_km[k] = robust_trend(x, v, s, scale=KM)
        if k in alerted:      # already below: an alert, not a forecast
            continue
        fc = forecast_crossing(tr, limits[k], rule.level, not_before=t_latest)
        if fc is not None and summary.distance_source is not None:
            fc.distance = True
            fc.crossing_m = limit_crossing(trk, limits[k], rule.level, not_before=x_latest)
        if fc is not None and fc.crossing_t <= t_latest + rule.horizon_days * DAY_S:
            forecasts[k] = fc
    summary.risk = "alert" if alerts else ("forecast" if forecasts else "ok")
    return summary


def summarize_fleet(records: Iterable[dict[str, Any]], rule: AlertConfig) -> list[VehicleSummary]:
    """Every vehicle's summary, ranked most at risk first (``rank`` 1 is the first)."""
    by_vehicle: dict[str, list[dict[str, Any]]] = {}
    for r in records:
        by_vehicle.setdefault(r["vehicle"], []).append(r)
    out = [summarize_vehicle(v, recs, rule) for v, recs in by_vehicle.items()]
    out.sort(key=VehicleSummary.sort_key)
    for i, s in enumerate(out, 1):
        s.rank = i
    return out
