"""Text output for people (without ``--json``): a few significant digits with units, ISO dates
for epoch times."""
from __future__ import annotations

import math
from datetime import datetime, timezone
from typing import Any, Mapping

#: data times (s) from this on are seconds since 1970 (1973 on; no record runs that long from 0)
EPOCH_FROM_S = 1e8


def num(v: Any, digits: int = 4, unit: str = "") -> str:
    """``v`` to ``digits`` significant digits, with ``unit`` after a space; ``-`` for a
    missing or non-finite value, integers and text as they are."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return str(v)
    text = f"{v:.{digits}g}" if isinstance(v, float) else str(v)
    return f"{text} {unit}" if unit else text


def data_time(t: float) -> str:
    """A data time (s) for a text line: ``t=12.35 s``, or the UTC time of an epoch time."""
    if not math.isfinite(t):
        return "t=-"
    if abs(t) >= EPOCH_FROM_S:
        when = datetime.fromtimestamp(t, tz=timezone.utc)
        return when.strftime("%Y-%m-%dT%H:%M:%S.") + f"{when.microsecond // 10000:02d}Z"
    return f"t={t:.2f} s"


def _pairs(d: Mapping[str, Any], skip_zero: bool = True) -> str:
    """``a 3, b 1``: a mapping's entries (zeros left out) for a text line."""
    return ", ".join(f"{k} {num(v)}" for k, v in d.items()
                     if not (skip_zero and isinstance(v, (int, float)) and v == 0))


def summary_lines(d: Mapping[str, Any]) -> list[str]:
    """The monitor's ``summary`` event as a few readable lines."""
    done = {"type", "windows_cut", "baseline", "data_s", "wall_s", "realtime_factor", "cpu_s"}
    parts = []
    if "windows" in d:
        parts.append(f"{d['windows']} windows fitted, {d.get('skipped', 0)} skipped")
        done |= {"windows", "skipped"}
    if "windows_cut" in d:
        parts.append(f"{d['windows_cut']} cut")
    if "baseline" in d:
        parts.append(f"estimator {d['baseline']}")
    speed = []
    if "data_s" in d:
        speed.append(f"{num(d['data_s'], 4, 's')} of data")
    if "wall_s" in d:
        speed.append(f"in {num(d['wall_s'], 3, 's')}")
    if d.get("realtime_factor") is not None:
        speed.append(f"({num(d['realtime_factor'], 3)}x real time)")
    text = " ".join(speed)
    if "cpu_s" in d:
        text += (", " if text else "") + f"CPU {num(d['cpu_s'], 3, 's')}"
    lines = ["summary: " + ", ".join(parts) + ("; " + text if text else "")]
    fr = d.get("frames")
    if isinstance(fr, Mapping):
        rej = fr.get("rejected") or {}
        text = (f"  frames: {fr.get('accepted', 0)} accepted, {sum(rej.values())} rejected"
                + (f" ({_pairs(rej)})" if any(rej.values()) else "")
                + f", {fr.get('ignored', 0)} ignored, {fr.get('lost', 0)} lost")
        if fr.get("time_base"):
            text += f"; time base {fr['time_base']}"
        lines.append(text)
        done.add("frames")
    rest = []
    for k, v in d.items():
        if k in done or k == "warnings" or v is None or v == [] or v == {}:
            continue
        if isinstance(v, Mapping):
            inner = _pairs(v, skip_zero=False) if all(
                not isinstance(x, (Mapping, list)) for x in v.values()) else f"{len(v)} entries"
            rest.append(f"{k.replace('_', ' ')}: {inner}")
        elif isinstance(v, list):
            rest.append(f"{k.replace('_', ' ')}: {', '.join(num(x) for x in v)}")
        else:
            rest.append(f"{k.replace('_', ' ')} {num(v)}")
    if rest:
        lines.append("  " + "; ".join(rest))
    lines += [f"  warning: {w}" for w in d.get("warnings") or []]
    return lines


__all__ = ["EPOCH_FROM_S", "data_time", "num", "summary_lines"]
