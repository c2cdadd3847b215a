"""Durable, append-only alert log (JSON lines, fsynced per event, before anybody sees it).

On open the last event of each parameter restores its state; an event is *new* only if its id
is unknown and it is later than its parameter's last one, so a replay after a crash repeats
nothing and a restarted monitor keeps an alert open. A torn last line is skipped.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

from typing import Union

from estimator.alerts.engine import AlertEvent
from estimator.alerts.forecast import ForecastEvent
from suspid.errors import InputError

StoredEvent = Union[AlertEvent, ForecastEvent]


class AlertStore:
    """Append-only alert file at ``path`` (created with its directories).

    ``events`` holds the events read and appended, ``last_event`` / ``last_forecast`` each
    parameter's latest alert or clear / forecast or withdrawal (by data time), and
    ``skipped_lines`` the unreadable lines found at open.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.events: list[StoredEvent] = []
        self.ids: set[str] = set()
        self.last_event: dict[str, AlertEvent] = {}
        self.last_forecast: dict[str, ForecastEvent] = {}
        self.skipped_lines = 0
        self._fd: int | None = None
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
                        d = json.loads(line)
                        ev: StoredEvent = (ForecastEvent.from_json(d) if str(d.get("type", ""))
                                           .startswith("forecast") else AlertEvent.from_json(d))
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
        if self._fd is None:
            raise InputError(f"{self.path}: the alert log is closed")
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
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> "AlertStore":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
