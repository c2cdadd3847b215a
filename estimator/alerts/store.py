"""Durable, append-only alert log (JSON lines; flushed and fsynced per event).

Write-ahead: :class:`~estimator.alerts.engine.AlertEngine` appends an event here and waits
for ``fsync`` before printing it or sending the CAN frame, so an event that anybody saw is
on disk. On start the log is read back: the last event of each parameter restores its state
(an open alert stays open, no second alert for the same episode), and an event is *new*
only if its id is unknown and its data time is later than the last logged event of its
parameter. Replaying the same CAN log after a crash therefore re-derives the old events and
suppresses them; a live monitor restarted mid-episode keeps the alert open. A line cut
short by a crash (no trailing newline) is ignored and the file is repaired by starting the
next record on a new line.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

from typing import Any, Mapping, Union

from estimator.alerts.engine import AlertEvent
from estimator.alerts.forecast import ForecastEvent
from suspid.errors import InputError

StoredEvent = Union[AlertEvent, ForecastEvent]


def event_from_json(d: Mapping[str, Any]) -> StoredEvent:
    """An alert, clear, forecast or forecast withdrawal from its JSON line."""
    if str(d.get("type", "")).startswith("forecast"):
        return ForecastEvent.from_json(d)
    return AlertEvent.from_json(d)


class AlertStore:
    """Append-only alert file.

    Parameters
    ----------
    path : str or Path
        The log; created (with parent directories) if missing.

    Attributes
    ----------
    events : list
        Events (:class:`AlertEvent`, :class:`ForecastEvent`) read at open plus those
        appended since.
    last_event : dict
        ``parameter -> latest alert or clear`` (by data time).
    last_forecast : dict
        ``parameter -> latest forecast or withdrawal`` (by data time).
    skipped_lines : int
        Unreadable lines found at open (a torn last write).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.events: list[StoredEvent] = []
        self.ids: set[str] = set()
        self.last_event: dict[str, AlertEvent] = {}
        self.last_forecast: dict[str, ForecastEvent] = {}
        self.skipped_lines = 0
        needs_newline = False
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            if self.path.exists():
                raw = self.path.read_bytes()
                needs_newline = bool(raw) and not raw.endswith(b"\n")
                for line in raw.decode("utf-8", errors="replace").splitlines():
                    if not line.strip():
                        continue
                    try:
                        ev = event_from_json(json.loads(line))
                    except (ValueError, KeyError, TypeError):
                        self.skipped_lines += 1
                        continue
                    self._remember(ev)
            self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        except OSError as exc:
            raise InputError(f"{self.path}: cannot open the alert log: {exc.strerror}") from None
        if needs_newline:
            self._write(b"\n")

    def _remember(self, ev: StoredEvent) -> None:
        self.events.append(ev)
        self.ids.add(ev.id)
        if isinstance(ev, ForecastEvent):
            lastf = self.last_forecast.get(ev.parameter)
            if lastf is None or ev.t >= lastf.t:
                self.last_forecast[ev.parameter] = ev
            return
        last = self.last_event.get(ev.parameter)
        if last is None or ev.t >= last.t:
            self.last_event[ev.parameter] = ev

    def is_new(self, ev: StoredEvent) -> bool:
        """``True`` if ``ev`` is not yet in the log (see the module docstring)."""
        if ev.id in self.ids:
            return False
        last: StoredEvent | None = (self.last_forecast.get(ev.parameter)
                                    if isinstance(ev, ForecastEvent)
                                    else self.last_event.get(ev.parameter))
        return last is None or ev.t > last.t + 1e-9

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            n = os.write(self._fd, view)
            view = view[n:]
        os.fsync(self._fd)

    def append(self, ev: StoredEvent) -> None:
        """Append one event as a JSON line and fsync it."""
        self._write((json.dumps(ev.to_json()) + "\n").encode("utf-8"))
        self._remember(ev)

    def close(self) -> None:
        if getattr(self, "_fd", None) is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> "AlertStore":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
