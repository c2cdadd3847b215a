"""Closing the loop: residual analysis, tracing the residual to a missing effect, augmented refit.

``diagnose(model, meas, params)`` is the entry point (``suspid diagnose``); the effect
library is :mod:`suspid.effects`, the fast nonlinear simulator
:mod:`suspid.nlsim` (base layer, shared with the effect library's injection).
"""
from estimator.diagnose.core import DiagnoseResult, Thresholds, Verdict, diagnose

__all__ = ["diagnose", "DiagnoseResult", "Thresholds", "Verdict"]
