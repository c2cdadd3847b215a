"""Measurement CSV (see CONTRACT.md): header row, one row per sample, SI units.

``t`` (s) strictly increasing; road columns are the model's ``roads`` (and ``_dot``);
measured columns any of the model's ``channels`` and ride heights; ``speed`` and ``odometer``
(:data:`AUX_CHANNELS`) are read but never fitted. Empty cells are missing samples (NaN);
unknown columns are ignored with a warning. A column annotated with its SI unit (``t [s]``)
is read as the named one; with another unit it is ignored with a warning (``t``: an error).
Every error names the file, the line and the column.
"""
from __future__ import annotations

import csv
import math
import re
from array import array
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np

from suspid.errors import InputError, require_file
from suspid.models.base import FloatArray, SuspensionModel


#: channels of the vehicle, not of a model, with their SI unit: never fitted, kept in
#: :attr:`Measurement.aux` (the fleet's distance per drive)
AUX_CHANNELS: dict[str, str] = {"speed": "m/s", "odometer": "m"}


@dataclass
class Measurement:
    """A measurement record on one time base.

    ``t`` (s) strictly increasing; ``road`` inputs by name (m, ``_dot`` m/s); ``measured``
    channels and ``aux`` vehicle channels (:data:`AUX_CHANNELS`), SI, NaN where missing;
    ``warnings`` non-fatal findings; ``source`` where the data came from.
    """

    t: FloatArray
    road: dict[str, FloatArray] = field(default_factory=dict)
    measured: dict[str, FloatArray] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    source: str = ""
    aux: dict[str, FloatArray] = field(default_factory=dict)


#: header of python-can's CSV log format (``can.CSVWriter``): CAN frames, not a measurement
PYTHON_CAN_CSV_LOG = ("timestamp", "arbitration_id", "extended", "remote", "error", "dlc", "data")
#: ``name [unit]`` or ``name (unit)`` in a header cell
_ANNOTATED = re.compile(r"^(?P<name>[^\[\]()]*?)\s*[\[(]\s*(?P<unit>[^\[\]()]*?)\s*[\])]$")
#: spellings of one SI unit, normalised
_SPELLINGS = {"m/s2": "m/s^2", "m/s²": "m/s^2", "m/s/s": "m/s^2", "m s^-2": "m/s^2",
              "rad/s2": "rad/s^2", "rad/s²": "rad/s^2", "rad/s/s": "rad/s^2", "sec": "s"}


def normalize_unit(unit: str) -> str:
    """A unit's spelling reduced to the one :meth:`SuspensionModel.column_units` uses
    (``m/s2`` -> ``m/s^2``)."""
    u = " ".join(unit.split())
    return _SPELLINGS.get(u, u)


def si_units(model: SuspensionModel, column: str) -> tuple[str, ...]:
    """The SI unit(s) of a column: the model's, or a vehicle channel's (empty: neither)."""
    units = model.column_units(column)
    return units or ((AUX_CHANNELS[column],) if column in AUX_CHANNELS else ())


def _annotated(cell: str, model: SuspensionModel) -> tuple[str, str | None]:
    """``(column name, None)`` for a header cell naming a column in its SI unit (or
    without a unit), ``(name, unit)`` for a known column annotated with another unit."""
    m = _ANNOTATED.match(cell)
    if m is None:
        return cell, None
    name, unit = m.group("name").strip(), " ".join(m.group("unit").split())
    units = si_units(model, name)
    if not units:
        return cell, None
    return (name, None) if normalize_unit(unit) in units else (name, unit)


def _parse_float(text: str, path: str, line: int, col: str) -> float:
    s = text.strip()
    if s == "" or s.lower() in ("nan", "na"):
        return math.nan
    try:
        # Python's float() also reads "1_000" and other scripts' digits: no CSV number
        if not s.isascii() or "_" in s:
            raise ValueError(s)
        v = float(s)
    except ValueError:
        raise InputError(f"{path}:{line}: column {col!r}: expected a number, got {s[:40]!r}") from None
    if math.isinf(v):
        raise InputError(f"{path}:{line}: column {col!r}: expected a finite number, got {s!r}")
    return v


#: runs of missing samples named one by one in a column's warning; more are counted
MAX_RUNS_NAMED = 5


def missing_runs(t: FloatArray, values: FloatArray) -> str:
    """The runs of missing samples (NaN) of ``values`` at times ``t`` (s), for a warning
    (``"150 missing samples in 2 runs: 100 at t 1-1.099 s, ...; not compared there"``, the
    first :data:`MAX_RUNS_NAMED` runs named); ``""`` when none."""
    gap = np.isnan(values)
    if not gap.any():
        return ""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], gap.view(np.int8), [0]))))
    runs = list(zip(edges[::2].tolist(), edges[1::2].tolist()))
    def span(a: int, b: int) -> str:
        return f"t {float(t[a]):.6g}" + (f"-{float(t[b - 1]):.6g} s" if b - a > 1 else " s")

    n = int(gap.sum())
    if len(runs) == 1:
        return f"{n} missing sample{'s' * (n != 1)} at {span(*runs[0])}; not compared there"
    named = [f"{b - a} at {span(a, b)}" for a, b in runs[:MAX_RUNS_NAMED]]
    more = f" and {len(runs) - MAX_RUNS_NAMED} more runs" if len(runs) > MAX_RUNS_NAMED else ""
    return f"{n} missing samples in {len(runs)} runs: " + ", ".join(named) + more + "; not compared there"


def _integrated(t: FloatArray, r: FloatArray, r_dot: FloatArray) -> FloatArray:
    """``r`` (m) with each run of missing samples filled by integrating ``r_dot`` (m/s) from the
    sample before it, the mismatch at the sample after it spread linearly over the run."""
    out = r.copy()
    gap = np.isnan(r)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], gap.view(np.int8), [0]))))
    for a, b in zip(edges[::2], edges[1::2]):  # missing samples a..b-1
        lo, hi = a - 1, b  # valid neighbours (may be outside the record)
        seg = np.arange(max(lo, 0), min(hi, r.size - 1) + 1)
        steps = 0.5 * (r_dot[seg[1:]] + r_dot[seg[:-1]]) * np.diff(t[seg])
        if lo < 0:  # a run at the start: integrate backwards from the sample after it
            out[:hi] = r[hi] - np.cumsum(steps[::-1])[::-1]
            continue
        path = r[lo] + np.concatenate(([0.0], np.cumsum(steps)))
        if hi < r.size:  # spread the mismatch at the far end, keep r[hi]
            path += (r[hi] - path[-1]) * (t[seg] - t[lo]) / (t[hi] - t[lo])
            path = path[:-1]
        out[lo + 1:lo + path.size] = path[1:]
    return out


def read_measurement(path: str | Path, model: SuspensionModel, *,
                     require_measured: bool = True) -> Measurement:
    """Read a measurement CSV for ``model``; a file without any measured channel of the model
    is an error if ``require_measured`` (``False`` for a road-only file). Raises
    :class:`InputError` for a missing/empty file, no ``t``, bad cells or rows, non-increasing
    ``t``, no channel."""
    p = require_file(path)
    name = str(path)
    try:
        fh = p.open(newline="", encoding="utf-8-sig")
    except OSError as exc:
        raise InputError(f"{name}: cannot open: {exc.strerror}") from None
    with fh:
        reader = csv.reader(fh)
        try:
            header = next(reader)
        except StopIteration:
            raise InputError(f"{name}: empty file, expected a header row with 't'") from None
        except (csv.Error, UnicodeDecodeError) as exc:
            raise InputError(f"{name}:1: not a CSV text file ({exc})") from None
        header = [h.strip() for h in header]
        off_unit: dict[int, tuple[str, str]] = {}
        for i, cell in enumerate(header):
            col, unit = _annotated(cell, model)
            if unit is None:
                header[i] = col
            elif col != "t":
                off_unit[i] = (col, unit)
            else:
                raise InputError(f"{name}:1: column {header[i]!r}: time in {unit!r}, expected s "
                                 "(convert the column to seconds)")
        if "t" not in header:
            seps = [sep for sep in (";", "\t", "|") if len(header) == 1 and sep in header[0]]
            hint = (f"; the header is separated by {seps[0]!r}, expected commas (a spreadsheet's "
                    "export: save as comma-separated with '.' decimals)" if seps else "")
            if header[:3] == list(PYTHON_CAN_CSV_LOG[:3]):
                hint = ("; this is a CAN log in python-can's CSV format, not a measurement CSV: "
                        f"convert it to a CAN log, e.g. python -m can.logconvert {name} "
                        f"{Path(name).with_suffix('.blf')}")
            raise InputError(f"{name}:1: no 't' column in the header (got {', '.join(header[:8])})"
                             + hint)
        dup = {h for h in header if h and header.count(h) > 1}
        if dup:
            raise InputError(f"{name}:1: duplicate column(s) {', '.join(sorted(dup))}")
        road_cols = set(model.roads) | {f"{r}_dot" for r in model.roads}
        measurable = list(model.channels) + list(model.ride_height_channels)
        known = {"t"} | road_cols | set(measurable) | set(AUX_CHANNELS)
        # a trailing separator (on the header, the rows or both) is an empty last column:
        # a row holds the named columns, then at most the header's cells or empty ones
        ncol = len(header)
        while ncol and not header[ncol - 1]:
            ncol -= 1
        unnamed_data = False
        warnings: list[str] = []
        unknown = [h or f"column {i + 1} (no name)" for i, h in enumerate(header[:ncol])
                   if h not in known and i not in off_unit]
        for i, (col, unit) in off_unit.items():
            warnings.append(f"{name}: ignoring column {header[i]!r}: {col} in {unit!r}, expected "
                            f"{' or '.join(si_units(model, col))} (SI; convert the column)")
        if unknown:
            warnings.append(f"{name}: ignoring column(s) not used by model {model.name}: "
                            f"{', '.join(unknown)}")
        used = [(i, h) for i, h in enumerate(header) if h in known]
        cols: dict[str, array] = {h: array("d") for _, h in used}  # 8 bytes/value
        line = 1
        try:
            for row in reader:
                line += 1
                if not row or all(not c.strip() for c in row):
                    continue
                if len(row) != ncol:
                    if len(row) < ncol or any(c.strip() for c in row[len(header):]):
                        raise InputError(f"{name}:{line}: expected {ncol} cells, got {len(row)}")
                    unnamed_data = unnamed_data or any(c.strip() for c in row[ncol:])
                for i, h in used:
                    v = _parse_float(row[i], name, line, h)
                    if h == "t" and math.isnan(v):
                        got = "is empty" if not row[i].strip() else f"is {row[i].strip()!r}"
                        raise InputError(f"{name}:{line}: column 't' {got} (data row "
                                         f"{len(cols['t']) + 1}), expected a time in s")
                    cols[h].append(v)
        except (csv.Error, UnicodeDecodeError) as exc:
            raise InputError(f"{name}:{line}: unreadable CSV ({exc})") from None
    if unnamed_data:
        where = (f"column {ncol + 1}" if len(header) == ncol + 1
                 else f"columns {ncol + 1}-{len(header)}")
        warnings.append(f"{name}: ignoring the values in {where} (no name in the header)")
    t = np.frombuffer(cols.pop("t"), dtype=float).copy()
    if t.size < 2:
        raise InputError(f"{name}: expected at least 2 data rows, got {t.size}")
    d = np.diff(t)
    if (d <= 0).any():
        k = int(np.flatnonzero(d <= 0)[0])
        raise InputError(f"{name}:{k + 3}: column 't': expected increasing time, got "
                         f"{float(t[k + 1]):.17g} after {float(t[k]):.17g}")
    road: dict[str, FloatArray] = {}
    measured: dict[str, FloatArray] = {}
    empty: list[str] = []
    aux: dict[str, FloatArray] = {}
    for h, vals in cols.items():
        arr = np.frombuffer(vals, dtype=float).copy()
        if h in AUX_CHANNELS:
            if not np.isnan(arr).all():
                aux[h] = arr
        elif h in road_cols:
            if np.isnan(arr).any() and (~np.isnan(arr)).sum() < 2:
                raise InputError(f"{name}: road column {h!r} has fewer than 2 values")
            road[h] = arr
        else:
            if np.isnan(arr).all():
                warnings.append(f"{name}: column {h!r} has no values; not compared")
                empty.append(h)
                continue
            runs = missing_runs(t, arr)
            if runs:
                warnings.append(f"{name}: column {h!r}: {runs}")
            measured[h] = arr
    for r in model.roads:
        if f"{r}_dot" in road and r not in road:
            raise InputError(f"{name}:1: road velocity column '{r}_dot' given without '{r}'")
    raw = {k: v.copy() for k, v in road.items()}
    for h, arr in raw.items():
        gap = np.isnan(arr)
        if not gap.any():
            continue
        other = raw.get(f"{h}_dot") if not h.endswith("_dot") else raw.get(h[:-4])
        if other is not None and not np.isnan(other[gap]).any():
            road[h] = (_integrated(t, arr, other) if not h.endswith("_dot")
                       else np.where(gap, np.gradient(other, t), arr))
            how = (f"integrated from {h}_dot" if not h.endswith("_dot")
                   else f"differentiated from {h[:-4]}")
        else:
            ok = ~gap
            road[h] = np.interp(t, t[ok], arr[ok])
            how = "filled by linear interpolation (the road's shape there is not known: "
            how += "the fit follows the guess; cut the record at the gap if it held excitation)"
        warnings.append(f"{name}: road column {h!r}: {int(gap.sum())} missing samples {how}")
    if not measured and require_measured:
        units = "".join(f"; column {header[i]!r} is {col} in {unit!r}, expected "
                        f"{' or '.join(si_units(model, col))}" for i, (col, unit) in off_unit.items())
        if empty:
            raise InputError(f"{name}: every measured column is empty ({', '.join(empty)}: no "
                             f"value in {t.size} rows); expected values of at least one")
        raise InputError(f"{name}:1: no measured channel for model {model.name}; expected any of "
                         f"{', '.join(measurable)}{units}")
    return Measurement(t=t, road=road, measured=measured, warnings=warnings, source=name,
                       aux=aux)


def write_measurement(path: str | Path, t: FloatArray, columns: Mapping[str, FloatArray]) -> None:
    """Write a measurement CSV with ``t`` first, then ``columns`` (SI units, ``%.10g``); an
    :class:`InputError` if the file cannot be created."""
    names = list(columns)
    data = np.column_stack([np.asarray(t, dtype=float)] + [np.asarray(columns[n], dtype=float)
                                                          for n in names])
    try:
        fh = open(path, "w", newline="", encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{path}: cannot create the CSV: {exc.strerror or exc}") from None
    with fh:
        fh.write(",".join(["t"] + names) + "\n")
        for row in data:
            fh.write(",".join("" if math.isnan(v) else f"{v:.10g}" for v in row) + "\n")
