"""EKF baseline: joint state and parameter estimation with filterpy (``--baseline ekf``)."""
