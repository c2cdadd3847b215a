"""Window configuration of the streaming identifier and its defaults from the physics.

Defaults come from the modes of the model at the nominal parameters (:func:`default_config`):
the window holds three periods and six decay times of the slowest mode, the step is half the
window, the decimation keeps 20 samples per period of the fastest mode, the road fusion
crosses over at 1.5 times the highest natural frequency, and models with ten or more free
parameters get a looser simplex tolerance finished by Gauss-Newton steps. The rules, the
numbers they give and the measurements behind each choice (with the commands that reproduce
them): ``docs/monitoring.md``, "Windows: defaults from the system's time constants" and
"Predictive-maintenance benchmark". The user-facing settings are the ``[window]`` table of
a ``--config`` file (``docs/configuration.md``), given here as :class:`WindowOptions`.
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
#: default Nelder-Mead xatol (log units), and the one for models with at least
#: ``MANY_FREE`` free parameters (module docstring)
XATOL = 2e-3
XATOL_MANY_FREE = 7e-3
MANY_FREE = 10
#: Gauss-Newton steps after Nelder-Mead with at least ``MANY_FREE`` free parameters
GAUSS_NEWTON_STEPS_MANY_FREE = 3
#: longest window plus two steps (s): a monitor's decoder buffers that span at up to 2 kHz
#: (2^21 rows per message); ``--window 1e5`` once asked for 2^28 rows and was killed for
#: 24 GB, ``--window 1e9`` ended in a MemoryError traceback
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
        Nelder-Mead restarts from the best vertex on the first window (default 4; the
        monitor's default with ten or more free parameters: 0, the Gauss-Newton steps
        finishing instead, module docstring).
    xatol : float
        Nelder-Mead simplex size tolerance in log-parameter units (2e-3 = 0.2 %, 2.5 times
        below the default ``sigma_floor``, so below every reported stderr); the only
        termination test besides the budget. The monitor's default (:func:`default_config`)
        is 7e-3 with ten or more free parameters (measurements: ``docs/monitoring.md``).
    warm_step : float
        Edge (log units) of the warm-start simplex per parameter, at least; the simplex is
        axis-aligned and centred on the extrapolated start (0.003 = 0.3 %, 1.5 ``xatol``:
        smaller stops Nelder-Mead before it has located the optimum, larger costs
        evaluations; a parameter that jumped further makes Nelder-Mead expand).
    warm_adaptive : bool
        Nelder-Mead's dimension-adapted coefficients (Gao and Han 2012: expansion
        ``1 + 2/n``, contraction ``0.75 - 1/(2n)``, shrink ``1 - 1/n``; used with more
        than four free parameters) on warm windows; ``False``: the standard ones (2, 0.5,
        0.5). The adapted coefficients keep a large simplex in many dimensions from
        stalling; a warm window's simplex is a few stderr across around a good
        prediction, where the standard ones converge in fewer evaluations. The monitor's
        default (:func:`default_config`) is ``False`` with ten or more free parameters.
    gauss_newton_step : bool
        After Nelder-Mead on a warm window, Gauss-Newton steps on one forward-difference
        Jacobian at its best vertex, each kept while it lowers the cost (``n_free``
        evaluations for the Jacobian, one per step;
        :meth:`~estimator.stream.windowfit.WindowFit.gauss_newton`); that Jacobian
        also gives the window's stderr. The monitor's default is on with ten or more free
        parameters.
    gauss_newton_steps : int
        Most Gauss-Newton steps on that Jacobian (default 1; the monitor's default with
        ten or more free parameters: 3).
    warm_predict : bool
        Start each warm window from the previous estimates extrapolated along their
        straight-line trend (3 windows) instead of the last estimate: a wearing damper
        moves 0.6-1.2 % per step, several ``xatol``.
    max_missing : float
        Skip a window when more than this fraction of a needed channel is missing.
    min_deflection : float
        Skip a window when the RMS suspension deflection (or, without a wheel channel, body
        motion) is below this (m) ...
    min_snr : float
        ... or below ``min_snr`` times the noise floor estimated from the data (default 3,
        above a parked car's ~1; why 3: ``docs/monitoring.md``).
    sigma_floor : float
        Relative standard error added in quadrature to every window's stderr (model error,
        within-window drift); default 0.005 = 0.5 % (``docs/monitoring.md``).
    cost : str
        ``"sse"`` (positions) or ``"frobenius"`` (every measured channel).
    road_fusion_hz : float
        Crossover (Hz) of the complementary filter that builds each road displacement fed to
        the fit from its measured displacement (below) and the integral of its measured
        velocity (above), when both are in the stream (:func:`estimator.stream.window.fuse_road`);
        0 uses the measured displacement as it is. Default from the model: ``1.5 f_fast``.
    road_lowpass_hz : float
        Cutoff (Hz, -6 dB) of a zero-phase Butterworth low-pass applied to each road
        displacement fed to the fit, after the fusion (:func:`estimator.stream.window.lowpass_road`);
        0 (default): none (it also removes true road content; ``docs/monitoring.md``).
    drift : tuple of str
        Free parameters refitted on each window with a linear drift,
        ``theta(t) = theta_end (1 + g (t - t_end))`` (``g`` one extra free parameter each),
        so that their estimate refers to the window's end (the tracker then takes no lag
        for them); empty: every parameter constant over the window. The dataclass default
        is empty; the monitor's (:func:`estimator.stream.pipeline.monitor_spec`) is every
        free damper and spring of the struts (:func:`strut_parameters`).
    drift_chunk_s : float
        Chunk length (s) over which the drifting parameters are held constant in the
        drift fit (one matrix exponential per chunk; default 0.2 s, ``docs/monitoring.md``).
    drift_iterations : int
        Largest number of Gauss-Newton steps of the drift fit where its first-order solve
        does not apply (:attr:`~estimator.stream.window.SlidingWindowIdentifier.first_order_drift`).
    drift_rate_sd : float
        Standard deviation (relative, 1/s) of a prior on each window's drift rate centred on
        that of the last estimates (once there are two); 0: no prior. Default 0.005
        (0.5 %/s; why: ``docs/monitoring.md``).
    offset : str
        A constant offset in a road column or a measured position channel (a sensor zero not
        at the rest position, :mod:`estimator.identify.offset`) is looked for on each cold
        window (the first fitted one, and any later one while no estimate has been
        accepted) until one is found: ``"remove"`` (default) subtracts it from that window
        and every later one, ``"keep"`` only names it (``suspid identify``'s ``--offset``).
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
    """The sliding window's settings a user gives; ``None`` takes the model's default.

    The command line gives ``window_s`` and ``step_s`` (``--window``, ``--step``), the
    ``[window]`` table of a ``--config`` file the rest (``docs/configuration.md``).
    :func:`estimator.stream.pipeline.monitor_spec` derives the defaults
    (:func:`default_config`) and applies these on top.

    Attributes
    ----------
    window_s, step_s : float or None
        Window length and step (s of data time).
    decimate : int or None
        Fit every ``decimate``-th sample.
    maxfev, first_maxfev : int or None
        Evaluation budgets (warm windows, first window).
    sigma_floor, min_deflection, min_snr, road_fusion_hz, road_lowpass_hz : float or None
        :class:`WindowConfig` fields of the same names (units there).
    drift : tuple of str or None
        Parameters fitted with a linear drift; ``()``: none; ``None``: every free damper
        and spring of the struts.
    drift_chunk_s, drift_rate_sd : float or None
        :class:`WindowConfig` fields of the same names.
    offset : {"remove", "keep"} or None
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
        """The :class:`WindowConfig` fields given, other than the window, step and decimation
        (which the defaults depend on)."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if f.name not in ("window_s", "step_s", "decimate")
                and getattr(self, f.name) is not None}


@dataclass
class AlertOptions:
    """The alert rule and forecast settings a user gives (``--alert-drop``, ``[alert]``).

    Attributes
    ----------
    drop : float
        Alert below ``(1 - drop) x nominal`` (fraction, default 0.3).
    confidence : float
        One-sided confidence of the bound (default 0.99).
    persistence_s : float or None
        Data time (s) a drop must persist (``None``: one window step).
    hysteresis : float
        Clear only above ``(1 - drop + hysteresis) x nominal`` (default 0.05).
    forecast_horizon_s : float or None
        Announce a predicted crossing due within this data time (s; ``None``: the
        library's default, 60 s).
    """

    drop: float = 0.3
    confidence: float = 0.99
    persistence_s: float | None = None
    hysteresis: float = 0.05
    forecast_horizon_s: float | None = None


@dataclass
class EkfOptions:
    """Settings of the EKF baseline (``[ekf]``); ``None`` takes the default.

    Attributes
    ----------
    params : tuple of str or None
        Parameters in the augmented state (default every free damper and spring).
    q : float or None
        Parameter random walk (relative per sqrt(s), default 0.005).
    decimate : int or None
        Run on every N-th sample (default 250 Hz or less).
    """

    params: tuple[str, ...] | None = None
    q: float | None = None
    decimate: int | None = None


@dataclass
class OutputOnlyOptions:
    """Settings of the output-only mode (``[output_only]``).

    Attributes
    ----------
    accel_channel : str or None
        Body acceleration channel (default the body's ``_ddot``).
    method : {"carma", "ar"}
    """

    accel_channel: str | None = None
    method: str = "carma"


def strut_parameters(model: SuspensionModel, params: Mapping[str, float],
                     free: list[str]) -> tuple[str, ...]:
    """The free dampers and springs of the model's struts (the suspension, not the tyres).

    Parameters
    ----------
    model : SuspensionModel
    params : mapping
        Parameter values (SI) for the model's site geometry.
    free : list of str
        Free parameter names.

    Returns
    -------
    tuple of str
        In the order of ``free``.
    """
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
    """Window defaults for ``model`` at nominal ``params`` sampled at ``fs`` (Hz).

    Parameters
    ----------
    model : SuspensionModel
    params : mapping
        Nominal parameter values (SI).
    fs : float
        Sample rate of the stream (Hz); 0 when not known yet (``decimate`` is then 1; set it
        with :func:`default_decimation` once the rate is known).
    n_free : int
        Number of free parameters (scales the evaluation budget; sets ``xatol``).

    Returns
    -------
    WindowConfig
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
