"""Maintenance alerts: confident-drop detection, durable alert log, CAN alert frames.

See :mod:`estimator.alerts.engine` for the decision logic, :mod:`estimator.alerts.store`
for the append-only file that survives a killed monitor, and :mod:`estimator.alerts.sinks`
for the outputs (JSON lines, the DBC ``SUSPID_Alert`` frame).
"""
from estimator.alerts.engine import AlertConfig, AlertEngine, AlertEvent
from estimator.alerts.store import AlertStore
from estimator.alerts.sinks import BusAlertSink, CallbackSink

__all__ = ["AlertConfig", "AlertEngine", "AlertEvent", "AlertStore", "BusAlertSink", "CallbackSink"]
