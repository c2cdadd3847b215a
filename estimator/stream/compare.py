"""Nelder-Mead windows vs the EKF on the same stream, built by :mod:`estimator.stream.pipeline`
from the same options: accuracy against a known truth (``rmse``, ``convergence_s``,
``alert_delay_s``, ``false_alarms``, ``error_over_stderr_rms``, ``forecast_first_*``) of the
values the alerts are decided on, and CPU time per sample.
"""
from __future__ import annotations

import csv
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from matplotlib.figure import Figure

from estimator.decode import load_log_as_measurement
from estimator.stream.config import AlertOptions, EkfOptions, WindowOptions
from estimator.stream.drivers import run_arrays
from estimator.stream.pipeline import (MonitorSpec, build_monitor,
                                       make_estimator, monitor_spec)
from suspid.can.logs import is_can_log
from suspid.errors import InputError, require_file
from suspid.io.csvio import read_measurement
from suspid.models.base import FloatArray, SuspensionModel


@dataclass
class RunRecord:
    """Everything one estimator produced on the stream (JSON lines of its events)."""

    name: str
    lines: list[dict[str, Any]] = field(default_factory=list)
    alerts: list[Any] = field(default_factory=list)
    cpu_s: float = 0.0
    wall_s: float = 0.0
    own_track: bool = False
    summary: dict[str, Any] = field(default_factory=dict)


def run_one(spec: MonitorSpec, t: FloatArray, data: Mapping[str, FloatArray]) -> RunRecord:
    """Stream ``(t, data)`` through the monitor of ``spec``; collect its events."""
    fs = 1.0 / float(np.median(np.diff(t)))
    channels = [c for c in data if c in spec.model.channels or c in spec.model.roads
                or c[:-4] in spec.model.roads or c in spec.model.ride_height_channels]
    c0, w0 = time.process_time(), time.perf_counter()
    est = make_estimator(spec, channels, fs)
    rec = RunRecord(spec.baseline, own_track=bool(getattr(est, "own_track", False)))
    mon = build_monitor(spec, lambda ev: rec.lines.append(ev.to_json()), estimator=est)
    run_arrays(t, data, spec.config.window_s, spec.config.step_s, mon.window)
    rec.cpu_s = time.process_time() - c0
    rec.wall_s = time.perf_counter() - w0
    rec.alerts = list(mon.alerts.emitted) if mon.alerts is not None else []
    rec.summary = mon.summary().to_json()
    return rec


def _series(rec: RunRecord, k: str) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Times, the values the alerts were decided on and their standard errors."""
    te, ve, se = [], [], []
    for l in rec.lines:
        if l["type"] != "estimate" or k not in l.get("stderr", {}):
            continue
        tr = (l.get("track") or {}).get(k)
        te.append(l["t"])
        if rec.own_track or tr is None:
            ve.append(l["params"][k])
            s = l["stderr"].get(k)
        else:
            ve.append(tr["value"])
            s = tr["stderr"]
        se.append(np.nan if s is None else s)
    return (np.array(te, dtype=float), np.array(ve, dtype=float),
            np.array(se, dtype=float))


def metrics(rec: RunRecord, t: FloatArray, truth: Mapping[str, FloatArray] | None,
            nominal: Mapping[str, float], drop: float, n_samples: int,
            tol: float = 0.05) -> dict[str, Any]:
    """The comparison metrics of one run (see the module docstring)."""
    est = [l for l in rec.lines if l["type"] == "estimate"]
    out: dict[str, Any] = {"estimates": len(est),
                           "skipped": sum(1 for l in rec.lines if l["type"] == "skip"),
                           "cpu_s": rec.cpu_s, "wall_s": rec.wall_s,
                           "cpu_us_per_sample": 1e6 * rec.cpu_s / max(n_samples, 1),
                           "params": {}}
    for key in ("augmented", "held", "nis", "nis_windows_inconsistent"):
        if key in rec.summary:
            out[key] = rec.summary[key]
    t0 = float(t[0])
    fc = [l for l in rec.lines if l["type"] == "forecast"]
    for k, nom in nominal.items():
        te, ve, se = _series(rec, k)
        m: dict[str, Any] = {"alerts": [a.t for a in rec.alerts
                                        if a.parameter == k and a.kind == "alert"]}
        fk = [f for f in fc if f["parameter"] == k]
        m["forecasts"] = len(fk)
        if truth is not None and k in truth and not te.size:
            below = np.flatnonzero(truth[k] < (1 - drop) * nom)
            m["crossing_t"] = float(t[below[0]]) if below.size else None
        if truth is not None and k in truth and te.size:
            tv = np.interp(te, t, truth[k])
            err = ve - tv
            rel = err / tv
            m["rmse"] = float(np.sqrt(np.mean(err ** 2)))
            m["rmse_pct"] = float(100 * np.sqrt(np.mean(rel ** 2)))
            if se.size == te.size and np.all(se > 0):
                m["error_over_stderr_rms"] = float(np.sqrt(np.mean((err / se) ** 2)))
            bad = np.flatnonzero(np.abs(rel) > tol)
            first_ok = bad[-1] + 1 if bad.size else 0   # within tol from here on
            m["convergence_s"] = float(te[first_ok] - t0) if first_ok < te.size else None
            below = np.flatnonzero(truth[k] < (1 - drop) * nom)
            crossing = float(t[below[0]]) if below.size else math.inf
            m["crossing_t"] = crossing if math.isfinite(crossing) else None
            m["false_alarms"] = sum(1 for a in m["alerts"] if a < crossing)
            after = [a for a in m["alerts"] if a >= crossing]
            m["alert_delay_s"] = (after[0] - crossing) if after else None
            early = [f for f in fk if f["t"] < crossing]
            if early and math.isfinite(crossing):
                f0 = early[0]
                m["forecast_first_t"] = f0["t"]
                m["forecast_lead_s"] = crossing - f0["t"]
                m["forecast_first_error_s"] = f0["crossing_t"] - crossing
                m["forecast_first_contains"] = bool(f0["crossing_t_low"] <= crossing
                                                    <= f0["crossing_t_high"])
                m["forecast_first_margin_s"] = float(min(crossing - f0["crossing_t_low"],
                                                         f0["crossing_t_high"] - crossing))
                m["forecast_contains_fraction"] = float(np.mean(
                    [f["crossing_t_low"] <= crossing <= f["crossing_t_high"] for f in early]))
            m["false_forecasts"] = (len(fk) if not math.isfinite(crossing) else 0)
        out["params"][k] = m
    return out


def load_stream(model: SuspensionModel, path: str | Path, dbc: Path | None = None,
                signal_map: Any = None, truth_csv: str | Path | None = None,
                channel: str | None = None, j1939_source: str | None = None
                ) -> tuple[FloatArray, dict[str, FloatArray], dict[str, FloatArray] | None]:
    """``(t, data, truth or None)`` of a CAN log or measurement CSV and its truth file."""
    p = require_file(str(path))
    if is_can_log(p):
        meas, _ = load_log_as_measurement(p, model, dbc, signal_map, channel=channel,
                                          j1939_source=j1939_source)
    else:
        meas = read_measurement(p, model)
    data = {**meas.measured, **meas.road}
    truth = None
    if truth_csv:
        try:
            with open(truth_csv, newline="") as fh:
                rows = list(csv.DictReader(fh))
        except OSError as exc:
            raise InputError(f"{truth_csv}: cannot read: {exc.strerror}") from None
        if not rows or "t" not in rows[0]:
            raise InputError(f"{truth_csv}: expected a header with a 't' column")
        try:
            tt = np.array([float(r["t"]) for r in rows])
            truth = {k: np.interp(meas.t, tt, [float(r[k]) for r in rows])
                     for k in rows[0] if k != "t" and k in model.param_names}
        except ValueError as exc:
            raise InputError(f"{truth_csv}: non-numeric value ({exc})") from None
    return np.asarray(meas.t), data, truth


def compare(model: SuspensionModel, t: FloatArray, data: Mapping[str, FloatArray],
            truth: Mapping[str, FloatArray] | None, *, fix: Mapping[str, float],
            nominal: Mapping[str, float] | None = None, init: Mapping[str, float] | None = None,
            window: WindowOptions | None = None, alert: AlertOptions | None = None,
            ekf: EkfOptions | None = None, source: str = "",
            road: str | None = None) -> tuple[dict[str, Any], list[RunRecord]]:
    """The sliding window and the EKF on one stream, on the same footing.

    Both get the same free parameters, starts, windows, alert rule and forecast horizon (as
    :func:`~estimator.stream.pipeline.monitor_spec` takes them; the window's tuning applies
    to the sliding window only). ``road`` ``None`` is ``measured`` when the stream carries
    every road, else ``unknown``. Returns the report and the two run records.
    """
    has_road = all(r in data for r in model.roads)
    warnings: list[str] = []
    if road is None:
        road = "measured" if has_road else "unknown"
        if not has_road:
            warnings.append("no road in the stream (driving data): the road under the tyres is "
                            "unknown (--road unknown): both estimators fit the body equations "
                            "on body accelerations and ride heights")
    if road == "measured" and not has_road:
        raise InputError(f"--road measured: the stream has no road input "
                         f"({', '.join(model.roads)}); give --road unknown for body "
                         "accelerations and ride heights")
    fs = 1.0 / float(np.median(np.diff(t)))
    wo = window or WindowOptions()
    alert = alert or AlertOptions()
    ekf = ekf or EkfOptions()
    kw: dict[str, Any] = dict(fix=fix, nominal=nominal, init=init, alert=alert, fs=fs,
                              inspection=False, ekf=ekf, road=road)
    nm_spec = monitor_spec(model, baseline="nm", window=wo, **kw)
    warnings += nm_spec.warnings
    # the EKF shares the window length and step (its alert persistence), not the fit tuning
    ekf_spec = monitor_spec(model, baseline="ekf",
                            window=WindowOptions(window_s=wo.window_s, step_s=wo.step_s), **kw)
    rec_nm = run_one(nm_spec, t, data)
    rec_ekf = run_one(ekf_spec, t, data)
    n = int(t.size)
    cfg = nm_spec.config
    channels = [c for c in list(model.channels) + list(model.ride_height_channels) if c in data]
    out: dict[str, Any] = {
        "model": model.name, "road": road, "warnings": warnings,
        "stream": {"source": source, "duration_s": float(t[-1] - t[0]), "fs_hz": fs,
                   "samples": n, "channels": channels},
        "window": {"window_s": cfg.window_s, "step_s": cfg.step_s, "decimate": cfg.decimate,
                   "budget": cfg.maxfev, "road_fusion_hz": cfg.road_fusion_hz,
                   "road_lowpass_hz": cfg.road_lowpass_hz},
        "ekf": {"augmented": rec_ekf.summary.get("augmented"),
                "held": rec_ekf.summary.get("held"),
                "q_param": ekf.q if ekf.q is not None else 0.005},
        "nominal": dict(nm_spec.nominal),
        "start": {k: nm_spec.params[k].value for k in nm_spec.nominal},
        "alert_drop": alert.drop, "forecast_horizon_s": nm_spec.forecast_horizon_s,
        "nm": metrics(rec_nm, t, truth, nm_spec.alert.nominal, alert.drop, n),
        "ekf_result": metrics(rec_ekf, t, truth, ekf_spec.alert.nominal, alert.drop, n),
    }
    return out, [rec_nm, rec_ekf]


def plot(path: str | Path, t: FloatArray, truth: Mapping[str, FloatArray] | None, recs: list[RunRecord],
         nominal: Mapping[str, float], drop: float) -> None:
    """One figure, a panel per parameter: the tracks (2-sigma bands), truth and alert limit."""
    names = list(nominal)
    fig = Figure(figsize=(9, 3.2 * max(1, len(names)) + 0.6))
    axes = fig.subplots(max(1, len(names)), 1, sharex=True, squeeze=False)[:, 0]
    for ax, param in zip(axes, names):
        _plot_param(ax, t, truth, recs, param, nominal[param], drop)
    axes[-1].set_xlabel("data time t (s)")
    fig.suptitle("sliding-window Nelder-Mead vs EKF (bands: +/- 2 stderr)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def _plot_param(ax: Any, t: FloatArray, truth: Mapping[str, FloatArray] | None,
                recs: list[RunRecord], param: str, nominal: float, drop: float) -> None:
    """One panel of :func:`plot`: ``param``'s tracks, truth and alert limit on ``ax``."""
    if truth is not None and param in truth:
        ax.plot(t, truth[param], "k-", lw=1.5, label=f"true {param}")
    ax.axhline((1 - drop) * nominal, color="r", ls="--", lw=1,
               label=f"alert limit {(1 - drop):.0%} x nominal")
    colors = {"nm": "C0", "ekf": "C1"}
    hatches = ("", "////", "\\\\", "xx")
    for i, rec in enumerate(recs):
        te, v, s = _series(rec, param)
        if not te.size:
            continue
        c = colors.get(rec.name, None)
        what = "estimate" if rec.own_track else "tracked (window end)"
        line, = ax.plot(te, v, ".-", ms=3, color=c, label=f"{rec.name.upper()} {what}")
        c = line.get_color()
        # own edges and hatch: a narrow band, or one inside the other, stays visible
        ax.fill_between(te, v - 2 * s, v + 2 * s, facecolor=c, alpha=0.15, lw=0,
                        hatch=hatches[i % len(hatches)], edgecolor=c,
                        label=f"{rec.name.upper()} +/- 2 stderr")
        for edge in (v - 2 * s, v + 2 * s):
            ax.plot(te, edge, color=c, lw=0.6, alpha=0.7)
        for a in rec.alerts:
            if a.parameter == param and a.kind == "alert":
                ax.axvline(a.t, color=c, ls=":", lw=1.5)
                # alternate sides: two alerts at the same time do not overprint
                side = -1 if i % 2 == 0 else 1
                ax.annotate(f"{rec.name.upper()} alert t = {a.t:.1f} s", (a.t, 0.04),
                            xycoords=("data", "axes fraction"), xytext=(2 * side, 0),
                            textcoords="offset points", color=c, rotation=90, va="bottom",
                            ha="right" if side < 0 else "left", fontsize=8)
    unit = "N s/m" if param.startswith("c") else ("N/m" if param.startswith("k") else "")
    ax.set_ylabel(f"{param} ({unit})" if unit else param)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
