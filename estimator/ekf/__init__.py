"""EKF baseline: joint state and parameter estimation with filterpy (``--baseline ekf``)."""
from estimator.ekf.filter import AugmentedEKF, EKFTuning
from estimator.ekf.stream import EKFWindowEstimator

__all__ = ["AugmentedEKF", "EKFTuning", "EKFWindowEstimator"]
