"""Maintenance alerts: confident-drop detection (:mod:`~estimator.alerts.engine`), forecasts,
the durable alert log (:mod:`~estimator.alerts.store`) and the outputs (:mod:`~estimator.alerts.sinks`)."""
from estimator.alerts.engine import AlertConfig, AlertEngine, AlertEvent
from estimator.alerts.forecast import (DEFAULT_HORIZON_S, Crossing, ForecastEngine, ForecastEvent,
                                       Trend, band_crossing, crossing,
                                       linear_trend)
from estimator.alerts.sinks import BusAlertSink, CallbackSink
from estimator.alerts.store import AlertStore

__all__ = ["AlertConfig", "AlertEngine", "AlertEvent", "AlertStore", "BusAlertSink", "CallbackSink",
           "DEFAULT_HORIZON_S", "Crossing", "band_crossing", "ForecastEngine", "ForecastEvent", "Trend", "crossing",
           "linear_trend"]
