"""Alert outputs: a callback (JSON lines on stdout) and the DBC ``SUSPID_Alert`` frame on a bus."""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Callable

from estimator.alerts.engine import AlertEvent

log = logging.getLogger(__name__)


@dataclass
class CallbackSink:
    """Call ``fn(event.to_json())`` for every event (the monitor prints JSON lines)."""

    fn: Callable[[dict[str, Any]], None]

    def emit(self, event: AlertEvent) -> None:
        self.fn(event.to_json())


@dataclass
class BusAlertSink:
    """Send each *alert* (not clears) as the DBC's ``SUSPID_Alert`` frame.

    Parameters
    ----------
    bus : can.BusABC
        A python-can bus (``send``).
    db : cantools Database
        suspid's DBC (the frame layout comes from it through
        :func:`suspid.can.codec.encode_alert`).
    """

    bus: Any
    db: Any
    counter: int = 0
    sent: int = 0
    errors: list[str] = field(default_factory=list)

    def emit(self, event: AlertEvent) -> None:
        if event.kind != "alert":
            return
        from suspid.can.codec import encode_alert

        msg = encode_alert(self.db, event.model, event.parameter, event.value, event.nominal,
                           severity=event.severity, counter=self.counter)
        self.counter = (self.counter + 1) % 15
        try:
            self.bus.send(msg)
            self.sent += 1
        except Exception as exc:  # a bus error must not stop the monitor; the file has it
            self.errors.append(str(exc))
            log.warning("could not send the alert frame: %s", exc)
