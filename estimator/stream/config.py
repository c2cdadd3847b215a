"""Window configuration of the streaming identifier and its defaults from the model's modes.

:func:`default_config` derives the window, step, decimation, road fusion and solver settings
from the modes at the nominal parameters; the rules and the measurements behind them are in
``docs/monitoring.md`` ("Windows: defaults from the system's time constants"). The user's
``[window]`` settings (``docs/configuration.md``) are :class:`WindowOptions`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Mapping


from estimator.identify.record import OFFSET_MODES
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
    """Sliding-window settings (defaults: :func:`default_config`, ``docs/monitoring.md``).

    Attributes
    ----------
    window_s, step_s : float
        Window length and step (s of data time).
    decimate : int
        Keep every ``decimate``-th sample for the fit.
    maxfev, first_maxfev : int
        Evaluation budgets (warm windows, first window).
    first_restarts : int
        Nelder-Mead restarts from the best vertex on the first window.
    xatol : float
        Nelder-Mead simplex size tolerance (log-parameter units); the only termination
        test besides the budget.
    warm_step : float
        Smallest edge (log units) of the warm-start simplex per parameter.
    warm_adaptive : bool
        Nelder-Mead's dimension-adapted coefficients on warm windows (else the standard ones).
    gauss_newton_step : bool
        Gauss-Newton steps after Nelder-Mead on a warm window
        (:meth:`~estimator.stream.windowfit.WindowFit.gauss_newton`); their Jacobian also
        gives the stderr.
    gauss_newton_steps : int
        Most Gauss-Newton steps on that Jacobian.
    warm_predict : bool
        Start each warm window from the last estimates' straight-line trend (3 windows).
    max_missing : float
        Skip a window when more than this fraction of a needed channel is missing.
    min_deflection, min_snr : float
        Skip a window when the RMS suspension deflection (or body motion) is below this (m)
        or below ``min_snr`` times the noise floor estimated from the data.
    sigma_floor : float
        Relative standard error added in quadrature to every window's stderr (model error,
        within-window drift).
    cost : str
        ``"sse"`` (positions) or ``"frobenius"`` (every measured channel).
    road_fusion_hz : float
        Crossover (Hz) of the road displacement / integrated velocity fusion
        (:func:`estimator.stream.window.fuse_road`); 0: the displacement as measured.
    road_lowpass_hz : float
        Cutoff (Hz, -6 dB) of a zero-phase low-pass on the fitted road
        (:func:`estimator.stream.window.lowpass_road`); 0: none.
    drift : tuple of str
        Free parameters refitted with a linear drift, ``theta(t) = theta_end (1 + g (t -
        t_end))``, so their estimate refers to the window's end; empty: none.
    drift_chunk_s : float
        Chunk length (s) over which the drifting parameters are held constant.
    drift_iterations : int
        Most Gauss-Newton steps of the drift fit where its first-order solve does not apply.
    drift_rate_sd : float
        Standard deviation (relative, 1/s) of a prior on the drift rate centred on the last
        estimates' rate; 0: no prior.
    offset : str
        ``"remove"`` or ``"keep"`` a constant sensor offset found on a cold window
        (:mod:`estimator.stream.offsets`).
    """

    window_s: float
    step_s: float
    decimate: int = 1
    maxfev: int = 160
    first_maxfev: int = 1000
    first_restarts: int = 4
    xatol: float = XATOL
    warm_step: float = 0.003
    warm_adaptive: bool = True
    gauss_newton_step: bool = False
    gauss_newton_steps: int = 1
    warm_predict: bool = True
    max_missing: float = 0.2
    min_deflection: float = 5e-4
    min_snr: float = 3.0
    sigma_floor: float = 0.005
    cost: str = "sse"
    road_fusion_hz: float = 0.0
    road_lowpass_hz: float = 0.0
    drift: tuple[str, ...] = ()
    drift_chunk_s: float = 0.2
    drift_iterations: int = 3
    drift_rate_sd: float = 0.005
    offset: str = "remove"

    def validate(self) -> None:
        """Raise :class:`UsageError` naming the first inconsistent setting."""
        if not (self.window_s > 0 and math.isfinite(self.window_s)):
            raise UsageError(f"--window: expected a window length > 0 s, got {self.window_s}")
        if not (0 < self.step_s <= 10 * self.window_s):
            raise UsageError(f"--step: expected 0 < step <= 10 x window, got {self.step_s} s")
        span = self.window_s + 2 * self.step_s
        if span > MAX_SPAN_S:
            raise UsageError(f"--window/--step: a window and two steps span {span:g} s, more than "
                             f"the {MAX_SPAN_S:g} s a monitor's decoder buffers (at up to 2 kHz); "
                             "give a shorter --window or --step, or use identify for a whole record")
        if self.decimate < 1:
            raise UsageError(f"window.decimate: expected an integer >= 1, got {self.decimate}")
        if self.offset not in OFFSET_MODES:
            raise UsageError(f"window.offset: expected one of {', '.join(OFFSET_MODES)}, "
                             f"got {self.offset!r}")
        if self.maxfev < 10 or self.first_maxfev < 10:
            raise UsageError(f"window.budget, window.first_budget: expected at least 10 "
                             f"evaluations, got {self.maxfev}, {self.first_maxfev}")
        if self.drift and not (self.drift_chunk_s > 0 and self.drift_iterations >= 1):
            raise UsageError(f"drift: expected drift_chunk_s > 0 s and drift_iterations >= 1, "
                             f"got {self.drift_chunk_s} s and {self.drift_iterations}")
        for opt, hz in (("window.road_fusion_hz", self.road_fusion_hz),
                        ("window.road_lowpass_hz", self.road_lowpass_hz)):
            if not (hz >= 0 and math.isfinite(hz)):
                raise UsageError(f"{opt}: expected a frequency >= 0 Hz (0: off), got {hz}")
        if not 0 <= self.max_missing < 1:
            raise UsageError(f"max_missing must be in [0, 1), got {self.max_missing}")


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

    def overrides(self) -> dict[str, Any]:
        """The fields given, other than window, step and decimation (the defaults' inputs)."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if f.name not in ("window_s", "step_s", "decimate")
                and getattr(self, f.name) is not None}


@dataclass
class AlertOptions:
    """The alert rule and forecast settings a user gives (``--alert-drop``, ``[alert]``).

    Attributes
    ----------
    drop : float
        Alert below ``(1 - drop) x nominal``.
    confidence : float
        One-sided confidence of the bound.
    persistence_s : float or None
        Data time (s) a drop must persist (``None``: one window step).
    hysteresis : float
        Clear only above ``(1 - drop + hysteresis) x nominal``.
    forecast_horizon_s : float or None
        Announce a predicted crossing due within this data time (s; ``None``: 60 s).
    """

    drop: float = 0.3
    confidence: float = 0.99
    persistence_s: float | None = None
    hysteresis: float = 0.05
    forecast_horizon_s: float | None = None


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
    names: set[str] = set()
    for site in model.strut_sites(params):
        names.update(k for k in (site.c_name, site.k_name) if k)
    return tuple(k for k in free if k in names)


def default_decimation(model: SuspensionModel, params: Mapping[str, float], fs: float) -> int:
    """``max(1, floor(fs / (20 f_fast)))``: at least 20 fitted samples per fastest period."""
    ms = modes(model, params)
    if not ms or not fs > 0:
        return 1
    return max(1, int(math.floor(fs / (20.0 * ms[-1].f_n))))


def default_config(model: SuspensionModel, params: Mapping[str, float], fs: float,
                   n_free: int) -> WindowConfig:
    """Window defaults for ``model`` at nominal ``params`` (SI).

    Parameters
    ----------
    fs : float
        Sample rate of the stream (Hz); 0 when not known yet (``decimate`` is then 1).
    n_free : int
        Number of free parameters (scales the budgets; sets the solver settings).
    """
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
