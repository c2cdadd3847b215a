"""Maintenance alerts: confident-drop detection, durable alert log, CAN alert frames.

See :mod:`estimator.alerts.engine` for the decision logic, :mod:`estimator.alerts.store`
for the append-only file that survives a killed monitor, and :mod:`estimator.alerts.sinks`
for the outputs (JSON lines, the DBC ``SUSPID_Alert`` frame), :mod:`estimator.alerts.forecast`
for trends and predicted limit crossings.
"""
from estimator.alerts.engine import AlertConfig, AlertEngine, AlertEvent
from estimator.alerts.forecast import (DEFAULT_HORIZON_S, Crossing, ForecastEngine, ForecastEvent,
                                       Trend, band_crossing, crossing,
                                       linear_trend)
from estimator.alerts.sinks import BusAlertSink, CallbackSink
from estimator.alerts.store import AlertStore

__all__ = ["AlertConfig", "AlertEngine", "AlertEvent", "AlertStore", "BusAlertSink", "CallbackSink",
           "DEFAULT_HORIZON_S", "Crossing", "band_crossing", "ForecastEngine", "ForecastEvent", "Trend", "crossing",
           "linear_trend"]
