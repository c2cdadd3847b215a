"""The fleet: identify every drive log on Dask, keep their history in SQLite, follow each
vehicle's parameters and write a static HTML report (``suspid fleet``; ``docs/fleet.md``).
"""
from estimator.alerts.engine import AlertConfig
from estimator.alerts.forecast import Trend
from estimator.fleet.analysis import VehicleSummary, summarize_fleet
from estimator.fleet.discover import DriveFile, find_drives
from estimator.fleet.drive import IdentifySettings, identify_drive
from estimator.fleet.history import History
from estimator.fleet.runner import (FleetConfig, FleetResult, ProgressBar, available_cpus,
                                    execute, local_workers, run_fleet)
from estimator.fleet.trend import Forecast, forecast_crossing, robust_trend

__all__ = ["AlertConfig", "VehicleSummary", "summarize_fleet", "DriveFile", "find_drives",
           "IdentifySettings", "identify_drive", "History", "FleetConfig", "FleetResult",
           "ProgressBar", "available_cpus", "local_workers", "execute", "run_fleet", "Forecast", "Trend", "forecast_crossing",
           "robust_trend"]
