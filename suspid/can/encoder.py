"""Measurement CSV -> the CAN log the sensor node would have sent (``suspid encode``).

Per CSV row, stamped with its ``t`` (+ ``t0``) at tick ``round((t - t_0) / period)`` (the
clock counts through a gap of missing rows): ``SN_Sync``, the sensor frames carrying any of
the CSV's columns (empty cells sent with ``Valid`` cleared), and every ``round(fs / 10)`` rows
an ``SN_Status`` frame; packed as the simulated node packs them (:class:`SensorEncoder`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import can
import numpy as np
from cantools.database.can import Database

from suspid.can.codec import STATE_RUNNING, SensorEncoder, encode_status, make_message
from suspid.can.logs import is_can_log, log_format, open_log_writer
from suspid.errors import InputError, UsageError, require_file
from suspid.io.csvio import Measurement, read_measurement
from suspid.models import get_model, infer_model


@dataclass
class EncodeResult:
    """Summary of an encoding run."""

    frames: int = 0
    samples: int = 0
    messages: list[str] = field(default_factory=list)
    saturated: dict[str, int] = field(default_factory=dict)
    model: str = ""


def measurement_frames(meas: Measurement, model_name: str, db: Database, t0: float = 0.0,
                       status_hz: float = 10.0, result: EncodeResult | None = None
                       ) -> Iterator[can.Message]:
    """Frames for every row of a measurement, stamped ``t + t0`` (s), ``SN_Status`` at
    ``status_hz`` (0: none); ``result`` filled with counts while iterating."""
    columns: dict[str, np.ndarray] = {**meas.measured, **meas.road}
    enc = SensorEncoder(db, model_name, list(columns))
    res = result if result is not None else EncodeResult()
    res.messages = [enc.sync.name] + [p.codec.name for p in enc.plans]
    res.model = model_name
    t = np.asarray(meas.t, dtype=float)
    n = t.size
    period = float(np.median(np.diff(t))) if n > 1 else 1e-3
    status_every = max(1, int(round(1.0 / (status_hz * period)))) if status_hz > 0 else 0
    names = list(columns)
    arrays = [np.asarray(columns[c], dtype=float) for c in names]
    status_counter = 0
    sensor_set = get_model(model_name).sensor_set
    rate = 1.0 / period if period > 0 else 0.0
    # the sensor clock's tick of every row, never twice the same
    ticks = np.zeros(n, dtype=np.int64)
    if n > 1 and period > 0:
        row = np.arange(n)
        ticks = np.maximum.accumulate(np.rint((t - t[0]) / period).astype(np.int64) - row) + row
    for i in range(n):
        ts = float(t[i]) + t0
        tick = int(ticks[i])
        fid, data = enc.sync_frame(tick, period)
        yield make_message(fid, data, ts)
        values = {c: float(a[i]) for c, a in zip(names, arrays)}
        for fid, data in enc.sample_frames(tick, values):
            yield make_message(fid, data, ts)
        res.frames += 1 + len(enc.plans)
        if status_every and i % status_every == 0:
            fid, data = encode_status(db, status_counter, STATE_RUNNING, rate, 0, 0, sensor_set)
            status_counter += 1
            res.frames += 1
            yield make_message(fid, data, ts)
        res.samples += 1
    res.saturated = dict(enc.saturated)


def encode_csv(csv_path: str | Path, out_path: str | Path, db: Database,
               model_name: str | None = None, t0: float = 0.0) -> EncodeResult:
    """Encode a measurement CSV into a CAN log (format by ``out_path`` suffix); raises
    :class:`InputError` for an unreadable CSV, :class:`UsageError` for an unknown suffix or
    model."""
    log_format(out_path, "output log")
    if is_can_log(csv_path):
        raise InputError(f"{csv_path}: --input must be a measurement CSV, got a CAN log "
                         f"({Path(csv_path).suffix}); encode writes logs, identify reads them")
    if model_name is None:
        p = require_file(csv_path)
        try:
            with p.open(encoding="utf-8-sig", errors="strict") as fh:
                header = fh.readline()
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"{p}:1: not a readable CSV text file ({exc})") from None
        model_name = infer_model([c.strip() for c in header.split(",")])
    model = get_model(model_name)
    meas = read_measurement(csv_path, model)
    if not math.isfinite(t0):
        raise UsageError(f"--t0 must be a finite number of seconds, got {t0}")
    res = EncodeResult()
    with open_log_writer(out_path) as writer:
        for msg in measurement_frames(meas, model_name, db, t0, result=res):
            writer.on_message_received(msg)
    return res
