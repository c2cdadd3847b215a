"""A record whose sample times jitter about a uniform grid, put on that grid.

The nonlinear refits of :func:`estimator.diagnose.diagnose` and the monitor's windows
step on a uniform grid. A record is uniform up to jitter when every sample lies within
``JITTER_FRACTION`` of a step of the grid with its first and last time and its sample
count; one missing sample shifts the rest by a step, so a gap is rejected. The channels
and the road are then interpolated onto the grid by a cubic spline (far less amplitude
loss than linear interpolation; docs/closing-the-loop.md); a missing sample stays missing.
"""
from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from suspid.io.csvio import Measurement
from suspid.models.base import FloatArray
from suspid.simulate import uniform_step

#: largest distance (in steps of the reference grid) of a sample from its grid point
JITTER_FRACTION = 0.25


def grid_jitter(t: FloatArray) -> tuple[float, float]:
    """The same-count, same-span grid's step ``h`` (s) and the largest ``|t[i] - (t[0] + i h)|`` (s).

    ``t``: sample times (s), increasing, at least two.
    """
    n = t.size
    h = float((t[-1] - t[0]) / (n - 1))
    grid = t[0] + h * np.arange(n)
    return h, float(np.max(np.abs(t - grid)))


def _spline(t: FloatArray, y: FloatArray, grid: FloatArray) -> FloatArray:
    """``y`` at ``grid`` by a cubic spline through its finite samples (missing ones stay NaN)."""
    y = np.asarray(y, dtype=float)
    ok = np.isfinite(y)
    out = np.full(grid.size, np.nan)
    if ok.sum() >= 4:
        out[ok] = CubicSpline(t[ok], y[ok])(grid[ok])
    elif ok.any():
        out[ok] = np.interp(grid[ok], t[ok], y[ok])
    return out


def to_uniform_grid(meas: Measurement) -> tuple[Measurement, str | None]:
    """The record on a uniform grid (the same object when it already was, or is not uniform
    up to jitter: the caller rejects it) and the warning naming the jitter when resampled.
    """
    t = np.asarray(meas.t, dtype=float)
    if t.size < 2 or uniform_step(t) is not None:
        return meas, None
    h, jit = grid_jitter(t)
    if not (h > 0 and jit <= JITTER_FRACTION * h):
        return meas, None
    grid = t[0] + h * np.arange(t.size)
    grid[-1] = t[-1]
    road = {k: _spline(t, v, grid) for k, v in meas.road.items()}
    measured = {k: _spline(t, v, grid) for k, v in meas.measured.items()}
    note = (f"{meas.source}: sample times jitter by up to {jit:.3g} s ({jit / h:.1%} of the "
            f"{h:.6g} s step) about a uniform grid; the measured channels and the road were "
            "resampled onto it by a cubic spline")
    return Measurement(grid, road, measured, list(meas.warnings), meas.source), note


__all__ = ["JITTER_FRACTION", "grid_jitter", "to_uniform_grid"]
