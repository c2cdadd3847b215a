"""Closing the loop: residual analysis, tracing the residual to a missing effect, augmented refit."""
from estimator.diagnose.core import DiagnoseResult, Thresholds, Verdict, diagnose

__all__ = ["diagnose", "DiagnoseResult", "Thresholds", "Verdict"]
