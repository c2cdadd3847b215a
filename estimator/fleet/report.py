"""The fleet report: one static HTML page (inline SVG plots, no server, no script): vehicles by
risk (``#vehicles``), a section per vehicle (drives in ``drives-NAME``), ``#unidentified`` and
``#failed``.
"""
from __future__ import annotations

import html
import math
import os
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Sequence

from estimator.alerts.engine import AlertConfig
from estimator.fleet.analysis import VehicleSummary
from estimator.fleet.drive import determined
from estimator.fleet.trend import DAY_S, Forecast
from suspid.errors import InputError, UsageError
from suspid.models import get_model

_CSS = """
body{font-family:system-ui,sans-serif;margin:1.5em;color:#222}
table{border-collapse:collapse;margin:.5em 0 1.5em}
th,td{border:1px solid #ccc;padding:3px 8px;text-align:left;font-size:14px}
th{background:#f0f0f0} tr.alert td{background:#fde2e2} tr.forecast td{background:#fff4d6}
.plots{display:flex;flex-wrap:wrap;gap:8px} svg{background:#fff;border:1px solid #ddd}
h2{margin-top:1.6em;border-bottom:1px solid #ccc}
"""


def _date(t: float | None, with_time: bool = False) -> str:
    if t is None or not math.isfinite(t):
        return ""
    fmt = "%Y-%m-%d %H:%M" if with_time else "%Y-%m-%d"
    try:
        return datetime.fromtimestamp(t, tz=timezone.utc).strftime(fmt)
    except (OverflowError, OSError, ValueError):
        return f"{t:.0f} s"


def _num(v: float) -> str:
    return f"{v:.4g}"


def trend_svg(s: VehicleSummary, name: str, width: int = 440, height: int = 210) -> str:
    """An inline SVG plot of one parameter's history, trend, limit and forecast."""
    drives = s.series(name)
    t = [float(d["t"]) for d in drives]
    v = [float(d["result"]["params"][name]) for d in drives]
    se = [d["result"].get("stderr", {}).get(name) for d in drives]
    se = [float(x) if x is not None and math.isfinite(float(x)) else 0.0 for x in se]
    tr = s.trends.get(name)
    fc = s.forecasts.get(name)
    nominal, limit = s.nominal[name], s.limits[name]
    t_lo, t_hi = min(t), max(t)
    if fc is not None:
        t_hi = max(t_hi, min(fc.crossing_t_high, t_hi + 3 * max(t_hi - t_lo, DAY_S)))
    if t_hi <= t_lo:
        t_hi = t_lo + DAY_S
    ys = [x - 2 * e for x, e in zip(v, se)] + [x + 2 * e for x, e in zip(v, se)] + [nominal, limit]
    y_lo, y_hi = min(ys), max(ys)
    pad = 0.08 * (y_hi - y_lo or abs(y_hi) or 1.0)
    y_lo, y_hi = y_lo - pad, y_hi + pad
    L, R, T, B = 58, 10, 22, 30
    W, H = width - L - R, height - T - B

    def X(tt: float) -> float:
        return L + W * (tt - t_lo) / (t_hi - t_lo)

    def Y(yy: float) -> float:
        return T + H * (1 - (yy - y_lo) / (y_hi - y_lo))

    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'class="trend" data-vehicle="{html.escape(s.vehicle)}" data-parameter="{name}">',
           f'<text x="{L}" y="14" font-size="13" font-weight="bold">{html.escape(name)}</text>']
    for i in range(5):
        yy = y_lo + (y_hi - y_lo) * i / 4
        out.append(f'<line x1="{L}" x2="{L + W}" y1="{Y(yy):.1f}" y2="{Y(yy):.1f}" '
                   'stroke="#eee"/>')
        out.append(f'<text x="{L - 4}" y="{Y(yy) + 4:.1f}" font-size="10" '
                   f'text-anchor="end">{_num(yy)}</text>')
    for i, anchor in enumerate(("start", "middle", "end")):
        tt = t_lo + (t_hi - t_lo) * i / 2
        out.append(f'<text x="{X(tt):.1f}" y="{T + H + 16}" font-size="10" '
                   f'text-anchor="{anchor}">{_date(tt)}</text>')
    out.append(f'<rect x="{L}" y="{T}" width="{W}" height="{H}" fill="none" stroke="#999"/>')
    if fc is not None:
        x1, x2 = X(max(fc.crossing_t_low, t_lo)), X(min(fc.crossing_t_high, t_hi))
        out.append(f'<rect x="{x1:.1f}" y="{T}" width="{max(x2 - x1, 1):.1f}" height="{H}" '
                   'fill="#f5a623" fill-opacity="0.25"><title>90 % interval of the limit '
                   f'crossing: {_date(fc.crossing_t_low)} to {_date(fc.crossing_t_high)}'
                   '</title></rect>')
        if t_lo <= fc.crossing_t <= t_hi:
            out.append(f'<line x1="{X(fc.crossing_t):.1f}" x2="{X(fc.crossing_t):.1f}" y1="{T}" '
                       f'y2="{T + H}" stroke="#d4880f" stroke-width="1.5"/>')
    out.append(f'<line x1="{L}" x2="{L + W}" y1="{Y(nominal):.1f}" y2="{Y(nominal):.1f}" '
               'stroke="#2a7" stroke-dasharray="4 3"><title>nominal</title></line>')
    out.append(f'<line x1="{L}" x2="{L + W}" y1="{Y(limit):.1f}" y2="{Y(limit):.1f}" '
               'stroke="#d22" stroke-width="1.5" stroke-dasharray="6 3"><title>limit '
               f'{_num(limit)}</title></line>')
    if tr is not None:
        out.append(f'<line x1="{X(t_lo):.1f}" x2="{X(t_hi):.1f}" y1="{Y(tr.at(t_lo)):.1f}" '
                   f'y2="{Y(tr.at(t_hi)):.1f}" stroke="#36c" stroke-width="1.5"/>')
    outliers = set(tr.outliers) if tr is not None else set()
    for i, (tt, x, e) in enumerate(zip(t, v, se)):
        if e > 0:
            out.append(f'<line x1="{X(tt):.1f}" x2="{X(tt):.1f}" y1="{Y(x - 2 * e):.1f}" '
                       f'y2="{Y(x + 2 * e):.1f}" stroke="#555"/>')
        fill = "none" if i in outliers else "#222"
        out.append(f'<circle cx="{X(tt):.1f}" cy="{Y(x):.1f}" r="2.6" fill="{fill}" '
                   f'stroke="#222"><title>{_date(tt, True)}: {_num(x)}</title></circle>')
    out.append("</svg>")
    return "".join(out)


def vehicle_anchor(name: str) -> str:
    """The HTML id of a vehicle's section: ``v-`` and the name, characters other than ASCII
    letters, digits and ``-`` written as ``_HEX_`` (stable and distinct).
    """
    return "v-" + "".join(c if (c.isascii() and c.isalnum()) or c == "-" else f"_{ord(c):x}_"
                          for c in name)


def _vehicle_row(s: VehicleSummary) -> str:
    last = s.latest
    fc = min(s.forecasts.items(), key=lambda kv: kv[1].crossing_t, default=None)
    fc_txt = (f"{fc[0]}: {_date(fc[1].crossing_t)} ({_date(fc[1].crossing_t_low)} to "
              f"{_date(fc[1].crossing_t_high)}; {_days(fc[1])}; {_km(fc[1])})" if fc else "")
    margin = s.margin()
    cells = [str(s.rank), f'<a href="#{vehicle_anchor(s.vehicle)}">{html.escape(s.vehicle)}</a>',
             s.risk, str(len(s.drives)), str(s.failed), str(len(s.unidentified)),
             ", ".join(a["parameter"] for a in s.alerts), fc_txt,
             _date(last["t"], True) if last else "",
             f"{100 * margin:.0f} %" if math.isfinite(margin) else ""]
    return (f'<tr class="{s.risk.replace(" ", "-")}">' +
            "".join(f"<td>{c}</td>" for c in cells) + "</tr>")


def render(vehicles: Sequence[VehicleSummary], drives: Sequence[dict[str, Any]],
           rule: AlertConfig) -> str:
    """The report page as HTML text."""
    failed = [d for d in drives if d["status"] == "failed"]
    unidentified = [d for d in drives if d["status"] == "unidentified"]
    n_ok = sum(1 for d in drives if d["status"] == "ok")
    parts = ["<!DOCTYPE html><html><head><meta charset='utf-8'>",
             "<title>suspid fleet report</title>", f"<style>{_CSS}</style></head><body>",
             "<h1>Suspension condition of the fleet</h1>",
             f"<p>{len(vehicles)} vehicles, {n_ok} drives identified, {len(unidentified)} "
             f"read but not identified (never in a trend, alert or forecast), "
             f"{len(failed)} failed logs. Limit: {100 * (1 - rule.drop):.0f} % of nominal; "
             f"alert when the {50 * (1.0 + math.erf(rule.z / math.sqrt(2.0))):.0f} % upper bound is "
             "below it in " + ("the latest drive" if rule.min_count == 1
                               else f"{rule.min_count} consecutive drives")
             + f"; forecasts with {100 * rule.level:.0f} % "
             f"intervals, in days after the vehicle's latest drive and, where the logs carry "
             "the vehicle's odometer or speed, in odometer km (the trend against distance). "
             "Generated "
             f"{_date(time.time(), True)} UTC.</p>",
             "<h2>Vehicles by risk</h2>", '<table id="vehicles"><thead><tr>',
             "".join(f"<th>{h}</th>" for h in ("Rank", "Vehicle", "Risk", "Drives", "Failed logs",
                                               "Not identified", "Alerts",
                                               "First forecast crossing (90 %)",
                                               "Latest drive (UTC)", "Margin to limit")),
             "</tr></thead><tbody>"]
    parts += [_vehicle_row(s) for s in vehicles]
    parts.append("</tbody></table>")
    for s in vehicles:
        roads = ", ".join(f"road {k}: {n}" for k, n in sorted(s.roads().items()))
        parts.append(f'<h2 id="{vehicle_anchor(s.vehicle)}">{s.rank}. {html.escape(s.vehicle)} '
                     f"({html.escape(s.model) or 'no identified drive'}, {len(s.drives)} drives"
                     f"{'; ' + roads if roads else ''}; {s.risk})</h2>")
        pos = s.latest_position()
        parts.append('<p class="distance">' + (
            "Distance: no distance signal in the logs (forecasts in days only)"
            if s.distance_source is None else
            f"Distance: from the {s.distance_source}"
            + (" (logged distance)" if s.distance_source == "speed" else "")
            + ("" if pos is None else f", {pos / 1e3:,.1f} km at the latest drive")) + "</p>")
        if s.unidentified:
            parts.append(f'<p class="warn-msg unidentified"><b>NOT IDENTIFIED</b> '
                         f"{len(s.unidentified)} drive(s) read but not identified, left out of "
                         "the trends, alerts and forecasts (table below)</p>")
        for msg in s.warnings:
            parts.append(f'<p class="warn-msg"><b>WARNING</b> {html.escape(msg)}</p>')
        for col, o in s.offsets.items():
            parts.append(f'<p class="warn-msg offset"><b>SENSOR OFFSET</b> {html.escape(col)} '
                         f"reads {_offset(col, o['median'], s.model)} at the rest position "
                         f"(median of {o['drives']} of {o['of']} drives, from "
                         f"{_offset(col, o['min'], s.model)} to {_offset(col, o['max'], s.model)};"
                         f" latest {_date(o['latest_t'], True)} UTC): a "
                         f"{'road' if o['kind'] == 'road' else 'position'} sensor zero not at "
                         f"rest, {'removed before each fit' if o['removed'] else 'kept in the fit'}"
                         "; recalibrate the sensor</p>")
        for a in s.alerts:
            parts.append(f'<p class="alert-msg"><b>ALERT</b> {html.escape(a["message"])} '
                         f'(first below in the drive of {_date(a["since_t"], True)} UTC)</p>')
        if s.monitored:
            parts.append('<table class="params"><tr><th>Parameter</th><th>Latest</th>'
                         "<th>Nominal</th><th>Limit</th><th>Trend per day</th>"
                         "<th>Forecast crossing</th><th>Forecast crossing (odometer)</th></tr>")
            for k in s.monitored:
                tr = s.trends.get(k)
                fc = s.forecasts.get(k)
                rate = ("" if tr is None else f"{_num(tr.rate * DAY_S)}" +
                        (f" ± {_num(tr.rate_stderr * DAY_S)}" if math.isfinite(tr.rate_stderr)
                         else ""))
                last = s.latest_value(k)
                parts.append(f"<tr><td>{k}</td><td>{'' if last is None else _num(last)}</td>"
                             f"<td>{_num(s.nominal[k])}</td><td>{_num(s.limits[k])}</td>"
                             f"<td>{rate}</td><td>{_date(fc.crossing_t) if fc else ''}"
                             f"{' (' + _days(fc) + ')' if fc else ''}</td>"
                             f"<td>{_km(fc) if fc else ''}</td></tr>")
            parts.append("</table><div class='plots'>")
            parts += [trend_svg(s, k) for k in s.monitored]
            parts.append("</div>")
        if s.drives or s.unidentified:
            parts.append(_drives_table(s))
    for title, tid, rows in (("Drives read but not identified", "unidentified", unidentified),
                             ("Failed logs", "failed", failed)):
        road = tid == "unidentified"     # the road a read drive was fitted with
        parts.append(f'<h2>{title}</h2><table id="{tid}"><thead><tr><th>Log</th><th>Vehicle</th>'
                     + ("<th>Road</th>" if road else "") + "<th>Reason</th></tr></thead><tbody>")
        for d in rows:
            cell = f"<td>{html.escape(str((d.get('result') or {}).get('road', '')))}</td>" if road else ""
            parts.append(f"<tr><td>{html.escape(d['path'])}</td><td>{html.escape(d['vehicle'])}</td>"
                         f"{cell}<td>{html.escape(d.get('error') or '')}</td></tr>")
        parts.append("</tbody></table>")
    parts[-1] += "</body></html>\n"
    return "\n".join(parts)


def _days(fc: Forecast) -> str:
    """``in 41 d (33 to 52 d)`` after the latest drive."""
    d, lo, hi = fc.days()
    return f"in {d:.0f} d ({lo:.0f} to {hi:.0f} d)" if math.isfinite(d) else ""


def _km(fc: Forecast) -> str:
    """``at 84,200 km (79,900 to 90,100 km)``, or why there is no crossing in km."""
    if not fc.distance:
        return "no distance signal"
    if fc.crossing_m is None:
        return "no crossing against distance"
    c, lo, hi = (x / 1e3 for x in fc.crossing_m)
    return f"at {c:,.0f} km ({lo:,.0f} to {hi:,.0f} km)"


def _drives_table(s: VehicleSummary) -> str:
    """A vehicle's drives: time, road, status, the load and monitored parameters, undetermined ones."""
    rows = sorted(s.drives + s.unidentified,
                  key=lambda r: (float(r["t"]) if r.get("t") is not None else math.inf,
                                 r["path"]))
    names = s.loads + s.monitored
    head = "".join(f"<th>{html.escape(k)}{' (load)' if k in s.loads else ''}</th>"
                   for k in names)
    odo_head = "<th>Odometer (km)</th>" if s.distance_source is not None else ""
    out = [f'<table class="drives" id="drives-{vehicle_anchor(s.vehicle)[2:]}"><thead><tr>'
           f"<th>Drive (UTC)</th><th>Road</th>{odo_head}<th>Status</th>{head}"
           "<th>Undetermined</th></tr></thead><tbody>"]
    for r in rows:
        res = r.get("result") or {}
        det = set(determined(res))
        cells = []
        for k in names:
            v = res.get("params", {}).get(k)
            se = (res.get("stderr") or {}).get(k)
            cells.append("not determined" if k not in det or v is None else
                         _num(float(v)) + (f" ± {_num(float(se))}" if se is not None else ""))
        und = [k for k in res.get("params", {}) if k not in det and k not in res.get("fixed", [])]
        status = r["status"] if r["status"] == "ok" else f"{r['status']}: {r.get('error') or ''}"
        pos = s.position(r) if r.get("t") is not None else None
        odo = ("" if s.distance_source is None else
               "<td></td>" if pos is None else f"<td>{pos / 1e3:,.1f}</td>")
        out.append(f'<tr class="{html.escape(r["status"])}"><td>{_date(r.get("t"), True)}</td>'
                   f"<td>{html.escape(str(res.get('road', '')))}</td>{odo}"
                   f"<td>{html.escape(status)}</td>"
                   + "".join(f"<td>{c}</td>" for c in cells)
                   + f"<td>{html.escape(', '.join(und))}</td></tr>")
    out.append("</tbody></table>")
    return "".join(out)


def _offset(column: str, value: float, model: str) -> str:
    """An offset in mm (or mrad for an angle) with its sign."""
    try:
        unit = (get_model(model).column_units(column) or ("m",))[0]
    except (KeyError, ValueError, UsageError):
        unit = "m"
    return f"{1e3 * value:+.3g} {'mrad' if unit == 'rad' else 'mm'}"


def prepare_report_folder(folder: str | Path) -> Path:
    """Create the report's folder before any drive is identified; returns the page's path.

    InputError when ``folder`` is a file, cannot be created or written, or its ``index.html`` is
    a folder.
    """
    d = Path(folder)
    if d.exists() and not d.is_dir():
        raise InputError(f"--report {folder}: is a file, expected a folder (the report is "
                         f"written to {d / 'index.html'})")
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--report {folder}: cannot create the folder "
                         f"({exc.strerror or exc})") from None
    page = d / "index.html"
    if page.is_dir():
        raise InputError(f"--report {folder}: {page} is a folder, expected the report page")
    if not os.access(d, os.W_OK) or (page.exists() and not os.access(page, os.W_OK)):
        raise InputError(f"--report {folder}: cannot write {page} (permission denied)")
    return page


def write_report(folder: str | Path, vehicles: Sequence[VehicleSummary],
                 drives: Sequence[dict[str, Any]], rule: AlertConfig) -> Path:
    """Write ``folder/index.html`` (the folder is created); returns its path."""
    d = Path(folder)
    d.mkdir(parents=True, exist_ok=True)
    p = d / "index.html"
    p.write_text(render(vehicles, drives, rule), encoding="utf-8")
    return p
