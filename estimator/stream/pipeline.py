"""The monitor's wiring, once: options -> estimator -> tracker -> alerts and forecasts -> sinks.

``suspid monitor`` and ``suspid compare`` build the same objects here: :func:`monitor_spec`
checks the options and derives the defaults, :func:`build_monitor` makes the
:class:`~estimator.stream.monitor.StreamMonitor`, :func:`run_monitor` streams a
:class:`Source` (CAN log, CSV or live bus) through it. Every output is a typed event handed to
one callback. The estimators in :data:`ESTIMATORS` are imported on first use.
"""
from __future__ import annotations

import importlib
import math
import sys
from dataclasses import dataclass, field, fields
from pathlib import Path
from statistics import NormalDist
from typing import Any, Callable, Literal, Mapping, cast

import numpy as np

from estimator.alerts import (DEFAULT_HORIZON_S, AlertConfig, AlertEngine, AlertStore,
                              BusAlertSink, CallbackSink, ForecastEngine)
from estimator.decode import DecodeListener
from estimator.decode.buffer import collision_notes
from estimator.decode.log_input import channel_notes, unparsed_hint
from estimator.identify import Parameters
from estimator.identify.inputs import CSV_SUFFIXES
from estimator.identify.regrid import to_uniform_grid
from estimator.identify.roadfree import resolve_road
from estimator.stream.config import (AlertOptions, EkfOptions, OutputOnlyOptions, WindowConfig,
                                     WindowOptions, default_config, default_decimation,
                                     strut_parameters)
from estimator.stream.drivers import (RECEIVE_BUFFER_S, CanWindowDriver, LiveStop, replay_log,
                                      run_arrays, run_bus)
from estimator.stream.events import Summary
from estimator.stream.offsets import OffsetStage
from estimator.stream.monitor import StreamMonitor
from estimator.stream.roadfree import road_unknown_params, road_unknown_window
from suspid.can.bus import open_bus
from suspid.can.logs import LOG_FORMATS, ReadStats, is_can_log
from suspid.errors import InputError, UsageError, require_file
from suspid.io.csvio import Measurement, read_measurement
from suspid.models.base import FloatArray, SuspensionModel


#: estimator name -> "module:factory"; a factory takes ``(spec, channels, fs)``
ESTIMATORS = {"nm": "estimator.stream.monitor:make_nm_estimator",
              "ekf": "estimator.ekf.stream:make_ekf_estimator",
              "output_only": "estimator.output_only:make_output_only_estimator",
              # the road unknown (--road unknown): the body equations, no road input
              "nm/unknown": "estimator.stream.roadfree:make_roadfree_estimator",
              "ekf/unknown": "estimator.ekf.roadfree:make_roadfree_ekf_estimator"}

#: output-only windows (s): a spectral estimate needs many body periods
OUTPUT_ONLY_WINDOW_S = 60.0
OUTPUT_ONLY_STEP_S = 30.0


@dataclass
class MonitorSpec:
    """Everything the monitor needs besides the stream."""

    model: SuspensionModel
    params: Parameters  # starting values of the free parameters, and the fixed ones
    nominal: dict[str, float]  # nominal value (SI) of every monitored parameter
    config: WindowConfig
    alert: AlertConfig
    baseline: str = "nm"  # "nm", "ekf" or "output_only"
    #: free parameters whose start was given; the EKF starts the others from the first
    #: window's sliding-window estimate
    start_given: set[str] = field(default_factory=set)
    decimate_given: bool = False  # config.decimate set explicitly (else from the sample rate)
    inspection: bool = True  # virtual damper test on each quarter-car estimate
    forecast_horizon_s: float = DEFAULT_HORIZON_S
    ekf_params: list[str] | None = None  # EkfOptions, checked
    ekf_q: float | None = None
    ekf_decimate: int | None = None
    accel_channel: str = ""
    oo_method: str = "carma"
    units: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    road: str | None = None  # --road; None: chosen on the first window (choose_road)
    drift_given: bool = False  # window.drift named parameters


def monitor_spec(model: SuspensionModel, *, fix: Mapping[str, float] | None = None,
                 nominal: Mapping[str, float] | None = None,
                 init: Mapping[str, float] | None = None, baseline: str = "nm",
                 road: str | None = None, window: WindowOptions | None = None,
                 alert: AlertOptions | None = None, ekf: EkfOptions | None = None,
                 output_only: OutputOnlyOptions | None = None, fs: float = 0.0,
                 inspection: bool = True) -> MonitorSpec:
    """Check the monitor's settings (raising :class:`UsageError` naming the first bad one) and
    derive its defaults from the model's modes (:func:`default_config`).

    ``fix``, ``nominal``, ``init`` (SI): known parameters, the monitored ones' nominal values
    (also their start), other starts. ``road`` ``None`` chooses on the first window;
    ``window``, ``alert``, ``ekf``, ``output_only`` are the user's settings
    (:mod:`estimator.stream.config`); ``fs`` (Hz) the sample rate when known.
    """
    wo, ao = window or WindowOptions(), alert or AlertOptions()
    eo, oo = ekf or EkfOptions(), output_only or OutputOnlyOptions()
    window_s, step, decimate = wo.window_s, wo.step_s, wo.decimate
    ekf_params = list(eo.params) if eo.params else None
    fix, nominal_in, init = dict(fix or {}), dict(nominal or {}), dict(init or {})
    horizon = DEFAULT_HORIZON_S if ao.forecast_horizon_s is None else ao.forecast_horizon_s
    if not 0 < ao.drop < 1:
        raise UsageError(f"--alert-drop: expected a fraction in (0, 1), got {ao.drop}")
    # the [alert] keys and --road are checked where they are read (suspid.cli)
    z = float(NormalDist().inv_cdf(ao.confidence))
    if baseline == "output_only":
        return _output_only_spec(model, nominal_in, ao, z, wo, horizon, oo)
    for k in list(fix) + list(nominal_in) + list(init):
        model.spec(k)
    if both := set(fix) & set(nominal_in):
        raise UsageError(f"parameter(s) {', '.join(sorted(both))} given both --fix and --nominal; "
                         "a fixed parameter is not monitored")
    if bad := set(fix) & set(init):
        raise UsageError(f"--init {sorted(bad)[0]}: the parameter is fixed (--fix)")
    params = Parameters.for_model(model, fix=fix, init=nominal_in)
    warnings: list[str] = []
    if road == "unknown":
        params, road_warnings = road_unknown_params(model, params)
        warnings += road_warnings
    elif model.scale_invariant and set(model.scale_invariant) <= set(params.free):
        m0 = next(p.name for p in model.params if p.kind in ("mass", "inertia"))
        params[m0].vary = False
        warnings.append(f"every mass, damper and spring is free, so only their ratios are "
                        f"identifiable; holding {m0} at {params[m0].value:g} "
                        f"{model.spec(m0).unit} (give --fix {m0}=VALUE)")
    if not params.free:
        raise UsageError("every parameter is fixed (--fix); nothing to monitor")
    values = params.valuesdict()
    nominal_all = {k: values[k] for k in params.free}
    for k, v in init.items():
        if k not in nominal_all:
            raise UsageError(f"--init {k}: not a free parameter"
                             + (" the road-unknown monitor follows" if road == "unknown" else ""))
        params[k].value = v
    cfg = default_config(model, values, fs, len(params.free))
    if road == "unknown" and window_s is None:
        # the band starts at 3 / window: below the body mode (docs/monitoring.md)
        cfg.window_s = max(cfg.window_s, road_unknown_window(model, values))
        cfg.step_s = max(0.05, round(round(cfg.window_s / 2.0 / 0.05) * 0.05, 2))
    if window_s is not None:
        cfg.window_s = window_s
        if step is None:
            cfg.step_s = max(0.05, round(window_s / 2.0, 2))
    if step is not None:
        cfg.step_s = step
    # the window's linear drift: by default every free damper and spring of the struts
    cfg.drift = strut_parameters(model, values, params.free) if road != "unknown" else ()
    given_drift = wo.drift
    if road == "unknown" and given_drift:
        raise UsageError(f"window.drift = {list(given_drift)}: does not apply with --road "
                         "unknown (each window's body equations are one linear fit of constant "
                         "parameters); give drift = [] or leave it out")
    # the fields given, other than window and step (the defaults' inputs)
    for f in fields(wo):
        if f.name not in ("window_s", "step_s") and getattr(wo, f.name) is not None:
            setattr(cfg, f.name, getattr(wo, f.name))
    cfg.validate()
    acfg = AlertConfig(nominal=dict(nominal_all), drop=ao.drop, z=z,
                       persistence_s=cfg.step_s if ao.persistence_s is None else ao.persistence_s,
                       hysteresis=ao.hysteresis)
    acfg.validate()
    aug = None
    if baseline == "ekf":
        if ekf_params:
            for k in ekf_params:
                model.spec(k)
            aug = [k for k in ekf_params if k in nominal_all]
            if not aug:
                raise UsageError(f"ekf.params = {ekf_params}: none of them is a free "
                                 "parameter")
            acfg.nominal = {k: v for k, v in nominal_all.items() if k in aug}
    elif baseline != "nm":
        raise UsageError(f"unknown estimator {baseline!r}; expected nm, ekf or output_only")
    return MonitorSpec(model, params, nominal_all, cfg, acfg, baseline=baseline,
                       start_given=set(nominal_in) | set(init),
                       decimate_given=decimate is not None, inspection=inspection,
                       forecast_horizon_s=horizon, ekf_params=aug, ekf_q=eo.q,
                       ekf_decimate=eo.decimate,
                       units={k: model.spec(k).unit for k in nominal_all}, warnings=warnings,
                       road=road, drift_given=bool(given_drift))


def _output_only_spec(model: SuspensionModel, nominal: Mapping[str, float], ao: AlertOptions,
                      z: float, wo: WindowOptions, horizon: float,
                      oo: OutputOnlyOptions) -> MonitorSpec:
    """:func:`monitor_spec` for the output-only mode (body mode from one accelerometer)."""
    channel = oo.accel_channel or f"{model.coords[0]}_ddot"
    if channel not in model.channels:
        raise UsageError(f"output_only.accel_channel {channel!r} is not a channel of model {model.name}")
    window, step = wo.window_s, wo.step_s
    w = window if window is not None else OUTPUT_ONLY_WINDOW_S
    s = step if step is not None else (w / 2.0 if window is not None else OUTPUT_ONLY_STEP_S)
    cfg = WindowConfig(window_s=w, step_s=s)
    cfg.validate()
    bad = [k for k in nominal if k not in ("f_body", "zeta_body")]
    if bad:
        raise UsageError(f"--nominal {bad[0]}: output-only mode monitors f_body and zeta_body")
    acfg = AlertConfig(dict(nominal), drop=ao.drop, z=z,
                       persistence_s=s if ao.persistence_s is None else ao.persistence_s,
                       hysteresis=min(ao.hysteresis, ao.drop / 2))
    acfg.validate()
    return MonitorSpec(model, Parameters.for_model(model), dict(nominal), cfg, acfg,
                       baseline="output_only", forecast_horizon_s=horizon,
                       accel_channel=channel, oo_method=oo.method,
                       units={"f_body": "Hz", "zeta_body": ""})


def choose_road(spec: MonitorSpec, t: FloatArray, data: Mapping[str, FloatArray]) -> str:
    """Set ``spec.road`` from the first window (times ``t``, s; channels SI) when ``--road``
    was not given, as :func:`estimator.identify.roadfree.resolve_road` decides for a record;
    the choice is written as a ``warning:`` line on stderr. Returns the road mode."""
    if spec.road is not None or spec.baseline == "output_only":
        return spec.road or "measured"
    model = spec.model
    road = {r: np.asarray(v, dtype=float) for r, v in data.items() if r in model.input_names}
    measured = {c: np.asarray(v, dtype=float) for c, v in data.items() if c not in road}
    mode, _, notes = resolve_road(model, Measurement(np.asarray(t, dtype=float), road, measured,
                                                     source="stream"), None)
    if mode == "unknown":
        spec.params, more = road_unknown_params(model, spec.params)
        notes += more
        if spec.drift_given:
            notes.append(f"window.drift {list(spec.config.drift)} ignored: with the road "
                         "unknown each window is one linear fit of constant parameters")
        spec.config.drift = ()
    spec.road = mode
    for w in notes:
        sys.stderr.write(f"warning: {w}\n")
    return mode


class ZeroRoad:
    """An estimator fed the model's roads as zero (``--road zero``: no road input, a free
    response from the window's initial state); road channels in the stream are not used."""

    road = "zero"

    def __init__(self, inner: Any, model: SuspensionModel) -> None:
        self.inner = inner
        self.model = model
        self.name = inner.name
        for a in ("lag", "lags", "overlap", "own_track"):
            if hasattr(inner, a):
                setattr(self, a, getattr(inner, a))

    def process(self, t: FloatArray, data: Mapping[str, FloatArray]) -> Any:
        """Delegate with every road and its rate set to zero."""
        return self.inner.process(t, dict(data, **{r: np.zeros(len(t)) for r in self.model.input_names}))

    def summary(self) -> dict[str, Any]:
        return dict(self.inner.summary(), road="zero")


def make_estimator(spec: MonitorSpec, channels: list[str], fs: float) -> Any:
    """The spec's estimator for a stream with ``channels`` sampled at ``fs`` (Hz): the body
    equations for ``spec.road`` ``unknown``, zero roads (:class:`ZeroRoad`) for ``zero``, else
    the stream's roads (every wheel's)."""
    road = spec.road or "measured"
    if spec.baseline == "nm" and not spec.decimate_given:
        spec.config.decimate = default_decimation(spec.model, spec.params.valuesdict(), fs)
    key = spec.baseline
    if spec.baseline != "output_only" and road == "unknown":
        key = f"{spec.baseline}/unknown"
    elif spec.baseline != "output_only":
        if road == "zero":
            channels = list(channels) + [r for r in spec.model.input_names if r not in channels]
        absent = [r for r in spec.model.roads if r not in channels]
        if len(absent) == len(spec.model.roads):
            raise InputError(f"the stream carries no road input {', '.join(absent)} "
                             f"(channels: {', '.join(channels) or 'none'}); input-output "
                             "identification needs it -- use --road unknown for body "
                             "accelerations and ride heights, --output-only for a body "
                             "accelerometer alone")
        if absent:
            # one wheel's road message never came (a sensor or its message missing)
            raise InputError(f"the stream carries no road input {', '.join(absent)} of model "
                             f"{spec.model.name}'s {', '.join(spec.model.roads)} (channels: "
                             f"{', '.join(channels)}); input-output identification needs "
                             "every wheel's road")
    mod, _, fn = ESTIMATORS[key].partition(":")
    factory: Callable[[MonitorSpec, list[str], float], Any] = getattr(
        importlib.import_module(mod), fn)
    est = factory(spec, channels, fs)
    return ZeroRoad(est, spec.model) if road == "zero" and spec.baseline != "output_only" else est


class LazyEstimator:
    """Builds the estimator on the first window (channels and sample rate known then)."""

    def __init__(self, spec: MonitorSpec) -> None:
        self.spec = spec
        self.inner: Any = None
        self.name = spec.baseline

    def _build(self, t: FloatArray, data: Mapping[str, FloatArray]) -> Any:
        present = [c for c, v in data.items() if np.mean(np.isfinite(v)) > 0.5]
        choose_road(self.spec, t, {c: data[c] for c in present})
        dt = float(np.median(np.diff(t)))
        self.inner = make_estimator(self.spec, present, 1.0 / dt if dt > 0 else 0.0)
        for a in ("lag", "lags", "overlap", "own_track", "road"):
            if hasattr(self.inner, a):
                setattr(self, a, getattr(self.inner, a))
        return self.inner

    def process(self, t: FloatArray, data: Mapping[str, FloatArray]) -> Any:
        """Build the estimator from the first window, then delegate."""
        inner = self.inner if self.inner is not None else self._build(t, data)
        return inner.process(t, data)

    def summary(self) -> dict[str, Any]:
        return self.inner.summary() if self.inner is not None else {}


def build_monitor(spec: MonitorSpec, emit: Callable[[Any], None], store: AlertStore | None = None,
                  estimator: Any = None) -> StreamMonitor:
    """The monitor of ``spec``: estimator (lazy unless given), tracker, alerts, forecasts.

    ``emit`` receives every event; ``store`` is the durable alert log; ``estimator`` a ready
    one (``compare`` builds it from the stream).
    """
    est = estimator if estimator is not None else LazyEstimator(spec)
    engine = None
    forecasts = None
    if spec.alert.nominal:
        engine = AlertEngine(spec.alert, spec.model.name, units=dict(spec.units), store=store,
                             sinks=[CallbackSink(emit)])
        forecasts = ForecastEngine({k: spec.alert.limit(k) for k in spec.alert.nominal},
                                   dict(spec.alert.nominal), spec.forecast_horizon_s,
                                   spec.model.name, dict(spec.units), publish=engine.publish)
        if store is not None:
            for k, ev in store.last_forecast.items():
                if ev.kind == "forecast" and k in forecasts.limits:
                    forecasts.active[k] = ev
    # the offset stage judges a window by the road-measured fit: not with the road unknown
    offsets = (OffsetStage(spec.model, spec.params, spec.config)
               if spec.baseline != "output_only" and spec.road in (None, "measured") else None)
    return StreamMonitor(est, emit, engine, forecasts=forecasts, offsets=offsets)


@dataclass
class Source:
    """Where the frames come from: a CAN log or CSV (``input``) or a live python-can bus."""

    input: str | None = None  # CAN log (replayed as fast as possible) or measurement CSV
    interface: str | None = None
    channel: str | None = None
    bitrate: int | None = None
    dbc: Path | None = None  # default suspid's
    signal_map: Any = None
    can_channel: str | None = None  # the bus channel of a multi-bus log (None: all)
    j1939_source: str | None = None  # the J1939 sender decoded (None: the first)
    #: None: the sensor's tick when the stream carries SN_Sync frames, else the timestamps
    time_source: Literal["timestamp", "tick"] | None = None
    duration: float | None = None  # live stop conditions (s of wall time)
    idle_timeout: float | None = 5.0
    rx_buffer_s: float = RECEIVE_BUFFER_S  # the live receiver's buffer (s of data)
    slcan_timestamps: bool = False  # time live SLCAN frames by the adapter's clock
    alert_frames: bool = True  # send SUSPID_Alert frames (live bus, or alert_interface)
    alert_interface: str | None = None
    alert_channel: str | None = None


def open_checked_bus(interface: str, channel: str | None, bitrate: int | None, what: str,
                     slcan_timestamps: bool = False) -> Any:
    """The bus through :func:`suspid.can.bus.open_bus`, errors prefixed with ``what``;
    ``slcan_timestamps``: the SLCAN adapter's own frame times."""
    if channel is None:
        raise UsageError(f"{what}: --channel is required with --interface {interface}")
    if interface == "slcan" and str(channel).lower() in ("pty", "pty:"):
        raise UsageError(f"{what}: --channel pty creates a node-side adapter (suspid node); give "
                         "the monitor the /dev/pts/N path the node printed")
    kw: dict[str, Any] = {"bitrate": bitrate} if bitrate else {}
    if slcan_timestamps:
        if interface != "slcan":
            raise UsageError(f"{what}: live.slcan_timestamps needs --interface slcan, got {interface}")
        kw["timestamps"] = True
    try:
        return open_bus(interface, channel, **kw)
    except UsageError as exc:
        raise UsageError(f"{what}: {exc}") from None


def run_monitor(spec: MonitorSpec, source: Source, emit: Callable[[Any], None],
                alert_file: str | Path | None = None) -> Summary:
    """Stream ``source`` through the monitor of ``spec`` (events to ``emit``); the summary."""
    store = AlertStore(alert_file) if alert_file else None
    mon = build_monitor(spec, emit, store)
    extra: dict[str, Any] = {}
    if spec.baseline == "output_only":
        extra = {"mode": "output_only", "channel": spec.accel_channel, "method": spec.oo_method}
    try:
        extra.update(run_source(source, spec, mon))
    finally:
        if store is not None:
            store.close()
    if spec.baseline != "output_only":
        extra["road"] = spec.road
    if store is not None:
        extra["alert_file"] = str(store.path)
    return mon.summary(extra)


def run_source(source: Source, spec: MonitorSpec, mon: StreamMonitor) -> dict[str, Any]:
    """Stream a log, a CSV or the live bus through ``mon``; the summary's source fields."""
    buses: list[Any] = []
    try:
        if source.input is not None:
            path = require_file(source.input)
            if is_can_log(path):
                return _run_log(source, spec, mon, buses)
            if path.suffix.lower() not in CSV_SUFFIXES:  # as identify: no guess at the format
                raise InputError(f"{path}: unknown input format {path.suffix!r}; expected .csv "
                                 f"or a CAN log ({', '.join(LOG_FORMATS)})")
            return _run_csv(source, spec, mon)
        return _run_live(source, spec, mon, buses)
    finally:
        for b in buses:
            try:
                b.shutdown()
            except Exception:  # pragma: no cover - best effort on the way out
                pass


def _can_driver(source: Source, spec: MonitorSpec, mon: StreamMonitor, buses: list[Any],
                live_bus: Any = None) -> tuple[DecodeListener, CanWindowDriver]:
    """The decoder (its buffer sized for the windows), the SUSPID_Alert frame sink (the live
    bus, or ``alert_interface``) given to the alert engine, and the window driver."""
    cfg = spec.config
    # rows per message: window + step at up to 2 kHz, power of two
    rows = 1 << max(12, math.ceil(math.log2(max(2.0, (cfg.window_s + 2 * cfg.step_s) * 2000.0))))
    listener = DecodeListener(spec.model, source.dbc, source.signal_map, capacity=rows,
                              growable=False, time_source=source.time_source or "auto",
                              arrival_slots=True, j1939_source=source.j1939_source)
    # a mapped signal the DBC gives in mm, g or deg without a scale: said before streaming
    for w in listener.signal_map.unit_warnings(listener.db, listener.model):
        sys.stderr.write(f"warning: {w}\n")
    bus = live_bus
    if source.alert_frames and source.alert_interface:
        bus = open_checked_bus(source.alert_interface, source.alert_channel, source.bitrate,
                               "live.alert_interface")
        buses.append(bus)
    if source.alert_frames and bus is not None and mon.alerts is not None:
        mon.alerts.sinks.append(BusAlertSink(bus, listener.db))
    return listener, CanWindowDriver(listener, cfg.window_s, cfg.step_s, mon.window,
                                     max_missing=cfg.max_missing)


def _run_log(source: Source, spec: MonitorSpec, mon: StreamMonitor, buses: list[Any]) -> dict[str, Any]:
    """Replay a CAN log as fast as possible through the decoder and the windows."""
    cfg = spec.config
    listener, drv = _can_driver(source, spec, mon, buses)
    stats = ReadStats()
    replay_log(drv, source.input, stats, channel=source.can_channel)
    listener.count_malformed(stats.malformed)
    bus_stats, bus_warnings = channel_notes(str(source.input), stats, listener.data_keys(),
                                            source.can_channel)
    mapped = {r.name for r in listener.routes.ordered}
    if listener.j1939 is not None:
        bus_warnings = bus_warnings + listener.j1939.warnings(str(source.input), mapped)
    for w in bus_warnings:
        sys.stderr.write(f"warning: {w}\n")
    if drv.windows == 0:
        fs = listener.frame_stats()
        if not fs["accepted"]:  # no data at all: a shorter window would not help
            rej = {k: v for k, v in cast("dict[str, int]", fs["rejected"]).items() if v}
            raise InputError(f"{source.input}: no accepted frame ({drv.frames} frames read, "
                             f"rejected {rej or 'none'}){unparsed_hint(str(source.input), stats)}"
                             + (listener.j1939.hint(mapped) if listener.j1939 is not None
                                else ""))
        raise InputError(f"{source.input}: {drv.frames} frames but less data than one window "
                         f"({cfg.window_s:g} s); give a shorter --window")
    frames = listener.frame_stats()
    frames.update(bus_stats)
    out: dict[str, Any] = {"frames": frames, "windows_cut": drv.windows}
    warnings = list(bus_warnings)
    if stats.damage:
        warnings.append(stats.damage)
    elif stats.truncated:
        warnings.append(f"{source.input}: the file ends inside a record (truncated)")
    warnings += collision_notes(drv.collisions, source.input, frames)
    if warnings:
        out["warnings"] = warnings
    return out


def _run_csv(source: Source, spec: MonitorSpec, mon: StreamMonitor) -> dict[str, Any]:
    """Stream a measurement CSV through the same windows."""
    cfg = spec.config
    meas = read_measurement(str(source.input), spec.model)
    # a logger's timing jitter: resampled onto the uniform grid (a gap still skips windows)
    meas, jitter = to_uniform_grid(meas)
    if jitter is not None:
        meas.warnings.append(jitter)
    data = {**meas.measured, **meas.road}
    if meas.t.size < 3 or meas.t[-1] - meas.t[0] < cfg.window_s:
        raise InputError(f"{source.input}: {meas.t[-1] - meas.t[0]:.3g} s of data, less than one "
                         f"window ({cfg.window_s:g} s); give a shorter --window")
    n = run_arrays(np.asarray(meas.t), data, cfg.window_s, cfg.step_s, mon.window)
    return {"windows_cut": n, "warnings": list(meas.warnings)}


def _run_live(source: Source, spec: MonitorSpec, mon: StreamMonitor, buses: list[Any]) -> dict[str, Any]:
    """Receive from a live python-can bus until idle, ``duration``, SIGINT or SIGTERM."""
    if source.interface is None:
        raise UsageError("give --input LOG or --interface I --channel C")
    bus = open_checked_bus(source.interface, source.channel, source.bitrate, "--interface",
                           slcan_timestamps=source.slcan_timestamps)
    buses.append(bus)
    listener, drv = _can_driver(source, spec, mon, buses, live_bus=bus)
    stop = LiveStop(duration=source.duration,
                    idle_timeout=None if not source.idle_timeout else source.idle_timeout)
    stop.install()
    try:
        n = run_bus(drv, bus, stop, buffer_s=source.rx_buffer_s)
    finally:
        stop.restore()
    frames = listener.frame_stats()
    warnings = collision_notes(drv.collisions, f"{source.interface} {source.channel}", frames)
    return {"frames": frames, "frames_received": n, "windows_cut": drv.windows,
            "stopped": stop.reason, **({"warnings": warnings} if warnings else {})}


def warn(spec: MonitorSpec) -> None:
    """Write the spec's warnings to stderr (one ``warning: ...`` line each)."""
    for w in spec.warnings:
        sys.stderr.write(f"warning: {w}\n")
