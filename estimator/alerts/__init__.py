"""Maintenance alerts: confident-drop detection (:mod:`~estimator.alerts.engine`), forecasts,
the durable alert log (:mod:`~estimator.alerts.store`) and the outputs (:mod:`~estimator.alerts.sinks`)."""
from estimator.alerts.engine import AlertConfig, AlertEngine
from estimator.alerts.forecast import (DEFAULT_HORIZON_S, ForecastEngine, ForecastEvent, Trend, crossing,
                                       linear_trend)
from estimator.alerts.sinks import BusAlertSink, CallbackSink
from estimator.alerts.store import AlertStore

__all__ = ["AlertConfig", "AlertEngine", "AlertStore", "BusAlertSink", "CallbackSink", "DEFAULT_HORIZON_S",
           "ForecastEngine", "ForecastEvent", "Trend", "crossing", "linear_trend"]
