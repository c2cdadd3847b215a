"""Alert outputs: a callback (the monitor's event sink) and the DBC ``SUSPID_Alert`` frame on a bus."""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Callable

from suspid.can.codec import encode_alert

log = logging.getLogger(__name__)


@dataclass
class CallbackSink:
    """Call ``fn(event)`` for every event (the monitor's sink turns it into a line)."""

    fn: Callable[[Any], None]

    def emit(self, event: Any) -> None:
        self.fn(event)


@dataclass
class BusAlertSink:
    """Send each *alert* and *forecast* (not clears or withdrawals) as the DBC's
    ``SUSPID_Alert`` frame on ``bus`` (``db``: suspid's DBC); a forecast has severity
    ``forecast``."""

    bus: Any
    db: Any
    counter: int = 0
    sent: int = 0
    errors: list[str] = field(default_factory=list)

    def emit(self, event: Any) -> None:
        if event.kind not in ("alert", "forecast"):
            return
        severity = "forecast" if event.kind == "forecast" else event.severity
        msg = encode_alert(self.db, event.model, event.parameter, event.value, event.nominal,
                           severity=severity, counter=self.counter)
        self.counter = (self.counter + 1) % 15
        try:
            self.bus.send(msg)
            self.sent += 1
        except Exception as exc:  # a bus error must not stop the monitor; the file has it
            self.errors.append(str(exc))
            log.warning("could not send the alert frame: %s", exc)
