"""What ``suspid identify`` reads: a measurement CSV or a CAN log, as one :class:`Measurement`.

:func:`read_input` is the one reader behind ``identify``, ``diagnose`` and ``fleet``. It
imports the CAN decoder (python-can, cantools) only for a CAN log: a CSV is read
without their import time.
"""
from __future__ import annotations

import importlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from suspid.errors import InputError
from suspid.io.csvio import Measurement, read_measurement
from suspid.models.base import SuspensionModel

if TYPE_CHECKING:
    from cantools.database import Database

    from suspid.can.signal_map import SignalMapLike

#: suffixes read as a measurement CSV
CSV_SUFFIXES = (".csv", ".txt", "")

#: the CAN log formats and reader, imported by name for a CAN log only
CAN_FORMATS, CAN_READER = "suspid.can.logs", "estimator.decode.log_input"


def read_input(path: str | Path, model: SuspensionModel,
               dbc: str | Path | Database | None = None,
               signal_map: SignalMapLike = None,
               channel: str | None = None,
               j1939_source: str | None = None) -> tuple[Measurement, dict[str, Any] | None]:
    """Read a measurement CSV (``.csv``, ``.txt``, no suffix) or a CAN log of a registered
    format for ``model``: the measurement (with a warning when it has no road and does not
    decay) and a CAN log's frame statistics (``None`` for a CSV).

    A CAN log is decoded with ``dbc`` (default suspid's ``suspension.dbc``) and the user's
    ``signal_map``, on bus ``channel`` (``can.channel``; unused for a CSV) and, for a J1939
    DBC, source address ``j1939_source``. :class:`InputError` (one line naming the file) for
    an unknown suffix or an unreadable or unusable file.
    """
    p = Path(path)
    frames: dict[str, Any] | None
    if p.suffix.lower() in CSV_SUFFIXES:
        meas, frames = read_measurement(p, model), None
        if channel is not None:
            meas.warnings.append(f"{p}: can.channel {channel} not used: a measurement CSV "
                                 "has no bus channels (the option selects one bus of a CAN log)")
    else:
        formats = importlib.import_module(CAN_FORMATS)
        if not formats.is_can_log(p):
            raise InputError(f"{p}: unknown input format {p.suffix!r}; expected .csv or a CAN "
                             f"log ({', '.join(formats.LOG_FORMATS)})")
        reader = importlib.import_module(CAN_READER)
        meas, frames = reader.load_log_as_measurement(p, model, dbc, signal_map,
                                                      channel=channel,
                                                      j1939_source=j1939_source)
    if model.roads and not meas.road and not decays(meas.measured):
        meas.warnings.append(
            f"{p}: no road input ({', '.join(model.roads)}) and the motion does not decay: "
            "the model can only fit it as a free response from an initial state (a release or "
            "drop test), so these parameters do not describe it; for driving data without a "
            "road or wheel-motion sensor use `suspid monitor --output-only` (body mode "
            "frequency and damping)")
    return meas, frames


def decays(measured: dict[str, Any]) -> bool:
    """Whether every channel's motion (RMS of its increments) in the last quarter of the record
    is below half of that in the first quarter: a free response decays, driving does not.
    """
    for v in measured.values():
        v = np.diff(np.asarray(v, dtype=float))
        q = v.size // 4
        if q < 2:
            return True          # too short to tell: no claim
        first, last = v[:q], v[-q:]
        first, last = first[np.isfinite(first)], last[np.isfinite(last)]
        if first.size < 2 or last.size < 2:
            continue
        if not _rms(last) < 0.5 * _rms(first):
            return False
    return True


def _rms(v: Any) -> float:
    """RMS of finite values without overflowing on huge ones."""
    top = float(np.max(np.abs(v))) if v.size else 0.0
    if top == 0.0:
        return 0.0
    return top * float(np.sqrt(np.mean((v / top) ** 2)))
