"""Window configuration of the streaming identifier and its defaults from the model's modes.

:func:`default_config` derives the window, step, decimation, road fusion and solver settings
from the modes at the nominal parameters; the rules and the measurements behind them are in
``docs/monitoring.md`` ("Windows: defaults from the system's time constants"). The user's
``[window]`` settings (``docs/configuration.md``) are :class:`WindowOptions`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

from suspid.errors import UsageError
from suspid.models.base import SuspensionModel
from suspid.models.modes import modes


#: default road-fusion crossover as a multiple of the highest natural frequency
ROAD_FUSION_MODES = 1.5
#: Nelder-Mead xatol (log units), and the one with at least ``MANY_FREE`` free parameters
XATOL = 2e-3
XATOL_MANY_FREE = 7e-3
MANY_FREE = 10
#: Gauss-Newton steps after Nelder-Mead with at least ``MANY_FREE`` free parameters
GAUSS_NEWTON_STEPS_MANY_FREE = 3
#: longest window plus two steps (s) a monitor's decoder buffers (at up to 2 kHz)
MAX_SPAN_S = 1000.0


@dataclass
class WindowConfig:
    """Sliding-window settings (defaults: :func:`default_config`, ``docs/monitoring.md``)."""

    window_s: float  # window length (s of data time)
    step_s: float  # step between window ends (s of data time)
    decimate: int = 1  # fit every decimate-th sample
    maxfev: int = 160  # evaluation budget of a warm window
    first_maxfev: int = 1000  # evaluation budget of the first window
    first_restarts: int = 4  # Nelder-Mead restarts on the first window
    xatol: float = XATOL  # simplex size tolerance (log units): the only test besides the budget
    warm_step: float = 0.003  # smallest edge (log units) of the warm-start simplex
    warm_adaptive: bool = True  # dimension-adapted Nelder-Mead coefficients on warm windows
    gauss_newton_step: bool = False  # Gauss-Newton steps after Nelder-Mead (their Jacobian: stderr)
    gauss_newton_steps: int = 1  # most Gauss-Newton steps on that Jacobian
    max_missing: float = 0.2  # skip a window missing more than this fraction of a channel
    min_deflection: float = 5e-4  # skip a window whose RMS strut deflection is below this (m) ...
    min_snr: float = 3.0  # ... or below this times the noise floor
    sigma_floor: float = 0.005  # relative stderr added in quadrature (model error, drift)
    cost: str = "sse"  # "sse" (positions) or "frobenius" (every measured channel)
    road_fusion_hz: float = 0.0  # crossover of the road fusion (window.fuse_road); 0: off
    road_lowpass_hz: float = 0.0  # cutoff of the road's zero-phase low-pass; 0: off
    #: free parameters fitted with a linear drift, ``theta_end (1 + g (t - t_end))``: their
    #: estimate refers to the window's end
    drift: tuple[str, ...] = ()
    drift_chunk_s: float = 0.2  # chunk (s) over which the drifting parameters are constant
    drift_iterations: int = 3  # most Gauss-Newton steps where the first-order drift fit fails
    drift_rate_sd: float = 0.005  # prior (relative, 1/s) on the drift rate around the recent one
    offset: str = "remove"  # "remove" or "keep" a sensor offset found (estimator.stream.offsets)

    def validate(self) -> None:
        """Raise :class:`UsageError` naming the first inconsistent window length or step (the
        ``[window]`` keys are checked where the configuration is read)."""
        if not (self.window_s > 0 and math.isfinite(self.window_s)):
            raise UsageError(f"--window: expected a window length > 0 s, got {self.window_s}")
        if not (0 < self.step_s <= 10 * self.window_s):
            raise UsageError(f"--step: expected 0 < step <= 10 x window, got {self.step_s} s")
        span = self.window_s + 2 * self.step_s
        if span > MAX_SPAN_S:
            raise UsageError(f"--window/--step: a window and two steps span {span:g} s, more than "
                             f"the {MAX_SPAN_S:g} s a monitor's decoder buffers (at up to 2 kHz); "
                             "give a shorter --window or --step, or use identify for a whole record")


@dataclass
class WindowOptions:
    """The sliding window's settings a user gives (``--window``, ``--step``, ``[window]``);
    ``None`` takes the model's default. Fields as :class:`WindowConfig`'s, except ``drift``:
    ``None`` is every free damper and spring of the struts, ``()`` none.
    """

    window_s: float | None = None
    step_s: float | None = None
    decimate: int | None = None
    maxfev: int | None = None
    first_maxfev: int | None = None
    sigma_floor: float | None = None
    min_deflection: float | None = None
    min_snr: float | None = None
    road_fusion_hz: float | None = None
    road_lowpass_hz: float | None = None
    drift: tuple[str, ...] | None = None
    drift_chunk_s: float | None = None
    drift_rate_sd: float | None = None
    offset: str | None = None


@dataclass
class AlertOptions:
    """The alert rule and forecast settings a user gives (``--alert-drop``, ``[alert]``)."""

    drop: float = 0.3  # alert below (1 - drop) x nominal
    confidence: float = 0.99  # one-sided confidence of the bound
    persistence_s: float | None = None  # data time (s) a drop must persist (None: one step)
    hysteresis: float = 0.05  # clear only above (1 - drop + hysteresis) x nominal
    forecast_horizon_s: float | None = None  # announce crossings due within this (s; None: 60)


@dataclass
class EkfOptions:
    """Settings of the EKF baseline (``[ekf]``): state parameters (default every free damper
    and spring), parameter random walk ``q`` (relative per sqrt(s), default 0.005) and
    decimation (default 250 Hz or less); ``None`` takes the default."""

    params: tuple[str, ...] | None = None
    q: float | None = None
    decimate: int | None = None


@dataclass
class OutputOnlyOptions:
    """Settings of the output-only mode (``[output_only]``): body acceleration channel
    (default the body's ``_ddot``) and method (``"carma"`` or ``"ar"``)."""

    accel_channel: str | None = None
    method: str = "carma"


def strut_parameters(model: SuspensionModel, params: Mapping[str, float],
                     free: list[str]) -> tuple[str, ...]:
    """The free dampers and springs of the model's struts (not the tyres), in ``free``'s order;
    ``params`` (SI) give the site geometry."""
    names = {k for site in model.strut_sites(params) for k in (site.c_name, site.k_name) if k}
    return tuple(k for k in free if k in names)


def default_decimation(model: SuspensionModel, params: Mapping[str, float], fs: float) -> int:
    """``max(1, floor(fs / (20 f_fast)))``: at least 20 fitted samples per fastest period."""
    ms = modes(model, params)
    if not ms or not fs > 0:
        return 1
    return max(1, int(math.floor(fs / (20.0 * ms[-1].f_n))))


def default_config(model: SuspensionModel, params: Mapping[str, float], fs: float,
                   n_free: int) -> WindowConfig:
    """Window defaults for ``model`` at nominal ``params`` (SI), a stream sampled at ``fs`` Hz
    (0 when not known yet: ``decimate`` 1) and ``n_free`` free parameters (the budgets scale
    with it; ten or more switch the solver settings)."""
    ms = modes(model, params)
    if not ms:
        raise UsageError(f"model {model.name} has no oscillating mode at the nominal parameters")
    slow = ms[0]
    period = slow.period if math.isfinite(slow.period) else 1.0 / slow.f_n
    tau = slow.tau if math.isfinite(slow.tau) else period
    window = math.ceil(max(3.0 * period, 6.0 * tau) * 2.0) / 2.0
    step = max(0.05, round(round(window / 2.0 / 0.05) * 0.05, 2))
    dec = default_decimation(model, params, fs)
    n = max(1, n_free)
    return WindowConfig(window_s=window, step_s=step, decimate=dec, maxfev=40 * n,
                        first_maxfev=250 * n,
                        xatol=XATOL_MANY_FREE if n >= MANY_FREE else XATOL,
                        warm_adaptive=n < MANY_FREE, gauss_newton_step=n >= MANY_FREE,
                        gauss_newton_steps=GAUSS_NEWTON_STEPS_MANY_FREE if n >= MANY_FREE else 1,
                        first_restarts=0 if n >= MANY_FREE else 4,
                        road_fusion_hz=ROAD_FUSION_MODES * ms[-1].f_n)
