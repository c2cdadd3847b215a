"""Streaming estimation: sliding-window identification of a suspension on a CAN stream.

:mod:`~estimator.stream.config`
    window defaults derived from the model's modes;
:mod:`~estimator.stream.window`
    one warm-started, budgeted Nelder-Mead fit per window, with excitation checks;
:mod:`~estimator.stream.accumulator`, :mod:`~estimator.stream.drivers`
    cutting windows out of arrays, CAN logs and live buses;
:mod:`~estimator.stream.monitor`
    estimates -> tracking, virtual damper test, JSON lines, alerts;
:mod:`~estimator.stream.tracker`
    parameter tracking with uncertainty;
:mod:`~estimator.stream.compare`
    the NM identifier against the EKF baseline;
:mod:`~estimator.stream.wear_streams`
    synthetic streams with drifting parameters (damper wear) and their CAN logs.

See ``docs/monitoring.md``.
"""
from estimator.stream.config import WindowConfig, default_config, default_decimation
from suspid.models.modes import modes
from estimator.stream.monitor import NMWindowEstimator, StepResult, StreamMonitor
from estimator.stream.window import SlidingWindowIdentifier, WindowResult

__all__ = ["WindowConfig", "default_config", "default_decimation", "modes", "NMWindowEstimator",
           "StepResult", "StreamMonitor", "SlidingWindowIdentifier", "WindowResult"]
