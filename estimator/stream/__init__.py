"""Streaming estimation: sliding-window identification of a suspension on a CAN stream
(``docs/monitoring.md``)."""
from estimator.stream.config import WindowConfig, default_config, default_decimation
from suspid.models.modes import modes
from estimator.stream.monitor import NMWindowEstimator, StepResult, StreamMonitor
from estimator.stream.window import SlidingWindowIdentifier, WindowResult

__all__ = ["WindowConfig", "default_config", "default_decimation", "modes", "NMWindowEstimator",
           "StepResult", "StreamMonitor", "SlidingWindowIdentifier", "WindowResult"]
