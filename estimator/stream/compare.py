"""Nelder-Mead windows vs the EKF on the same stream: accuracy, speed, alerts.

Both estimators see the same samples through the same windows (the NM one fits each
window, the EKF filters the samples new in each window) and feed identical alert engines.
Metrics (``truth`` known for synthetic streams):

``rmse`` / ``rmse_pct``
    RMS over estimates of ``estimate(t) - truth(t)`` (SI and relative %), ``t`` the data
    time at the window end (the contract's ``t``).
``convergence_s``
    data time from the stream start after which every later estimate stays within 5 % of
    the truth (``null`` if never).
``alert_delay_s``
    first alert of the parameter minus the time the truth crossed ``(1 - drop) x nominal``.
``false_alarms``
    alerts raised while the truth was still above the limit.
``cpu_us_per_sample``
    process CPU time of the estimator divided by the samples of the stream.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from estimator.alerts import AlertConfig, AlertEngine
from estimator.stream.drivers import run_arrays
from estimator.stream.monitor import StreamMonitor
from suspid.models.base import FloatArray


@dataclass
class RunRecord:
    """Everything one estimator produced on the stream."""

    name: str
    lines: list[dict[str, Any]] = field(default_factory=list)
    alerts: list[Any] = field(default_factory=list)
    cpu_s: float = 0.0
    wall_s: float = 0.0


def run_one(estimator: Any, t: FloatArray, data: Mapping[str, FloatArray], window_s: float,
            step_s: float, alert_cfg: AlertConfig, model_name: str) -> RunRecord:
    """Stream ``(t, data)`` through ``estimator`` with an alert engine; collect the lines."""
    rec = RunRecord(estimator.name)
    eng = AlertEngine(AlertConfig(dict(alert_cfg.nominal), alert_cfg.drop, alert_cfg.z,
                                  alert_cfg.persistence_s, alert_cfg.min_count,
                                  alert_cfg.hysteresis), model_name)
    mon = StreamMonitor(estimator, rec.lines.append, eng)
    c0, w0 = time.process_time(), time.perf_counter()
    run_arrays(t, data, window_s, step_s, mon.window)
    rec.cpu_s = time.process_time() - c0
    rec.wall_s = time.perf_counter() - w0
    rec.alerts = list(eng.emitted)
    return rec


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
    t0 = float(t[0])
    for k, nom in nominal.items():
        pts = [(l["t"], l["params"][k]) for l in est if k in l.get("params", {})]
        m: dict[str, Any] = {"alerts": [a.t for a in rec.alerts if a.parameter == k and a.kind == "alert"]}
        if truth is not None and k in truth and pts:
            te = np.array([p[0] for p in pts])
            ve = np.array([p[1] for p in pts])
            tv = np.interp(te, t, truth[k])
            err = ve - tv
            rel = err / tv
            m["rmse"] = float(np.sqrt(np.mean(err ** 2)))
            m["rmse_pct"] = float(100 * np.sqrt(np.mean(rel ** 2)))
            bad = np.flatnonzero(np.abs(rel) > tol)
            if bad.size == 0:
                m["convergence_s"] = float(te[0] - t0)
            elif bad[-1] + 1 < te.size:
                m["convergence_s"] = float(te[bad[-1] + 1] - t0)
            else:
                m["convergence_s"] = None
            limit = (1 - drop) * nom
            below = np.flatnonzero(truth[k] < limit)
            crossing = float(t[below[0]]) if below.size else math.inf
            m["crossing_t"] = crossing if math.isfinite(crossing) else None
            m["false_alarms"] = sum(1 for a in m["alerts"] if a < crossing)
            after = [a for a in m["alerts"] if a >= crossing]
            m["alert_delay_s"] = (after[0] - crossing) if after else None
        out["params"][k] = m
    return out


def plot(path: str, t: FloatArray, truth: Mapping[str, FloatArray] | None, recs: list[RunRecord],
         param: str, nominal: float, drop: float) -> None:
    """One figure: the parameter's tracks (with 2-sigma bands) against the truth and limit."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 4.5))
    if truth is not None and param in truth:
        ax.plot(t, truth[param], "k-", lw=1.5, label=f"true {param}")
    ax.axhline((1 - drop) * nominal, color="r", ls="--", lw=1,
               label=f"alert limit {(1 - drop):.0%} x nominal")
    colors = {"nm": "C0", "ekf": "C1"}
    for rec in recs:
        est = [l for l in rec.lines if l["type"] == "estimate" and param in l["params"]]
        if not est:
            continue
        te = np.array([l["t"] for l in est])
        v = np.array([l["params"][param] for l in est])
        s = np.array([l["stderr"].get(param) or np.nan for l in est], dtype=float)
        c = colors.get(rec.name, None)
        ax.plot(te, v, ".-", ms=3, color=c, label=f"{rec.name.upper()} estimate")
        ax.fill_between(te, v - 2 * s, v + 2 * s, color=c, alpha=0.2, lw=0)
        for a in rec.alerts:
            if a.parameter == param and a.kind == "alert":
                ax.axvline(a.t, color=c, ls=":", lw=1.5)
                ax.annotate(f"{rec.name} alert", (a.t, (1 - drop) * nominal), color=c,
                            rotation=90, va="bottom", ha="right", fontsize=8)
    ax.set_xlabel("data time t (s)")
    unit = "N s/m" if param.startswith("c") else ("N/m" if param.startswith("k") else "")
    ax.set_ylabel(f"{param} ({unit})" if unit else param)
    ax.set_title(f"{param}: sliding-window Nelder-Mead vs EKF (bands: +/- 2 stderr)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
