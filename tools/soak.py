"""Soak benchmark (not CI): a long simulated sensor stream processed at speed, windows identified.

The simulated node (:class:`firmware_sim.node.SensorNode`, quarter2, random road, 500 Hz,
sensor noise, 2 % random frame loss) produces frames; a bounded
:class:`~estimator.decode.listener.DecodeListener` (ring capacity ``--capacity`` rows per
message) validates and buffers them; a :class:`~estimator.stream.drivers.CanWindowDriver`
cuts a window every ``step`` s of data and hands it to the monitor's window identifier
(:class:`~estimator.stream.monitor.NMWindowEstimator`, warm-started budgeted Nelder-Mead,
tracker and virtual damper test; ``m1`` held at its nominal value, as ``suspid monitor``
does), through a :class:`~estimator.stream.monitor.StreamMonitor` without output. The
window length and step are the monitor's defaults for quarter2 (``default_config``) unless
``--window``/``--step`` are given. Per window, the alignment time (the decoder's
``aligned``) and the identification time (the fit) are measured; RSS
(``/proc/self/statm``) is recorded at intervals. ``--no-identify`` keeps the decoder and the
alignment only (10 s window every 1 s unless given).

Usage::

    python tools/soak.py                     # 1 hour of data
    python tools/soak.py --duration 300      # 5 min variant
    python tools/soak.py --no-identify       # decoder + alignment only

Prints a table: data time, frames, RSS (MB), windows, align time and identification time
per window (ms, mean and max over the interval), the last ``c1`` estimate, and the wall rate
(frames/s, node simulation included). Flat RSS and flat window time are the target.
"""
from __future__ import annotations

import argparse
import math
import os
import time
from typing import Any, Sequence

from estimator.decode.listener import DecodeListener
from firmware_sim.faults import FaultConfig
from firmware_sim.node import NodeConfig, SensorNode


def rss_mb() -> float:
    """Resident set size of this process (MB)."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6


def _monitor(rate: float, window: float | None, step: float | None) -> tuple[Any, Any]:
    """The monitor's quarter2 window identifier (``suspid monitor`` defaults) and its config."""
    from estimator.identify import Parameters
    from estimator.stream.config import default_config, default_decimation
    from estimator.stream.monitor import NMWindowEstimator, StreamMonitor
    from suspid.models import get_model

    model = get_model("quarter2")
    params = Parameters.for_model(model)
    params["m1"].vary = False  # scale invariant: the monitor holds the first mass
    values = params.valuesdict()
    cfg = default_config(model, values, 0.0, len(params.free))
    if window is not None:
        cfg.window_s = window
        if step is None:
            cfg.step_s = max(0.05, round(window / 2.0, 2))
    if step is not None:
        cfg.step_s = step
    cfg.decimate = default_decimation(model, values, rate)
    cfg.validate()
    est = NMWindowEstimator(model, params, cfg, ["x1", "x2", "x1_dot", "x2_dot"])
    return StreamMonitor(est, lambda line: None), cfg


def soak(duration: float = 3600.0, window: float | None = None, step: float | None = None,
         capacity: int = 1 << 14, report_every: float = 300.0, loss: float = 0.02,
         identify: bool = True, seed: int = 0) -> list[dict[str, float]]:
    """Run the soak; one record per ``report_every`` seconds of data.

    Returns
    -------
    list of dict
        ``t`` (data s), ``frames``, ``rss_mb``, ``windows`` (in the interval), ``align_ms``
        and ``align_ms_max``, ``fit_ms`` and ``fit_ms_max`` (NaN without identification),
        ``c1`` (last estimate, NaN if none), ``frames_per_s`` (wall rate over the interval,
        node simulation included), ``window_s`` and ``step_s`` (the windows used).
    """
    from estimator.stream.drivers import CanWindowDriver

    cfg = NodeConfig(model="quarter2", scenario="random", duration=duration, speed=0.0,
                     channels=["x1", "x2", "x1_dot", "x2_dot", "r", "r_dot"], seed=seed,
                     faults=FaultConfig(loss=loss))
    node = SensorNode(cfg)
    lst = DecodeListener("quarter2", node.db, capacity=capacity)
    align_times: list[float] = []
    fit_times: list[float] = []
    last: dict[str, float] = {"c1": math.nan}
    aligned = lst.aligned

    def timed_aligned(*a: Any, **k: Any) -> Any:
        t0 = time.perf_counter()
        out = aligned(*a, **k)
        align_times.append(time.perf_counter() - t0)
        return out

    lst.aligned = timed_aligned  # type: ignore[method-assign]
    if identify:
        mon, wcfg = _monitor(cfg.rate, window, step)
        win_s, step_s = wcfg.window_s, wcfg.step_s

        def on_window(t: Any, data: Any) -> None:
            t0 = time.perf_counter()
            res = mon.window(t, data)
            fit_times.append(time.perf_counter() - t0)
            if res.values:
                last["c1"] = float(res.values["c1"])
    else:
        win_s, step_s = window or 10.0, step or 1.0

        def on_window(t: Any, data: Any) -> None:
            pass

    drv = CanWindowDriver(lst, win_s, step_s, on_window)
    on = drv.on_message
    rows: list[dict[str, float]] = []
    next_rep = report_every
    n = n_rep = 0
    wall_rep = time.perf_counter()

    def ms(xs: list[float], f: Any) -> float:
        return 1e3 * f(xs) if xs else math.nan

    for msg in node.frames():
        on(msg)
        n += 1
        t = msg.timestamp
        if t >= next_rep:
            now = time.perf_counter()
            rows.append({"t": t, "frames": n, "rss_mb": rss_mb(), "windows": len(align_times),
                         "align_ms": ms(align_times, lambda x: sum(x) / len(x)),
                         "align_ms_max": ms(align_times, max),
                         "fit_ms": ms(fit_times, lambda x: sum(x) / len(x)),
                         "fit_ms_max": ms(fit_times, max), "c1": last["c1"],
                         "frames_per_s": (n - n_rep) / (now - wall_rep),
                         "window_s": win_s, "step_s": step_s})
            align_times.clear()
            fit_times.clear()
            n_rep, wall_rep = n, now
            next_rep += report_every
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    """Command line of the tool."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=3600.0, help="data seconds (default 3600)")
    ap.add_argument("--window", type=float, default=None,
                    help="window length s (default: the monitor's, 3 s for quarter2; 10 s "
                         "with --no-identify)")
    ap.add_argument("--step", type=float, default=None,
                    help="window step s (default: the monitor's, 1.5 s; 1 s with --no-identify)")
    ap.add_argument("--every", type=float, default=None,
                    help="report interval s of data (default duration/12)")
    ap.add_argument("--capacity", type=int, default=1 << 14, help="ring rows per message")
    ap.add_argument("--loss", type=float, default=0.02, help="random frame loss (default 0.02)")
    ap.add_argument("--no-identify", action="store_true",
                    help="decoder and window alignment only (no window identifier)")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = soak(a.duration, a.window, a.step, a.capacity, a.every or a.duration / 12, a.loss,
                identify=not a.no_identify)
    meta = rows[-1] if rows else {"window_s": math.nan, "step_s": math.nan}
    print(f"soak: quarter2 random road, 500 Hz, {100 * a.loss:g} % loss, {a.duration:g} s of data, "
          f"window {meta['window_s']:g} s every {meta['step_s']:g} s"
          f"{'' if a.no_identify else ' identified (NM)'}, ring {a.capacity} rows; wall "
          f"{time.perf_counter() - t0:.0f} s, CPU {time.process_time():.0f} s")
    print("| data t (s) | frames | RSS (MB) | windows | align mean (ms) | align max (ms) | "
          "identify mean (ms) | identify max (ms) | c1 (N s/m) | frames/s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['t']:.0f} | {r['frames']:.0f} | {r['rss_mb']:.1f} | {r['windows']:.0f} | "
              f"{r['align_ms']:.2f} | {r['align_ms_max']:.2f} | {r['fit_ms']:.1f} | "
              f"{r['fit_ms_max']:.1f} | {r['c1']:.0f} | {r['frames_per_s']:.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
