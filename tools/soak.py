"""Soak benchmark (not CI): a long simulated sensor stream processed at speed through the decoder.

The simulated node (:class:`firmware_sim.node.SensorNode`, quarter2, random road, 500 Hz,
sensor noise, 2 % random frame loss) produces frames; a bounded
:class:`~estimator.decode.listener.DecodeListener` (ring capacity ``--capacity`` rows per
message) validates and buffers them; every ``--step`` seconds of data a window of
``--window`` s is aligned (what the monitor's window identifier consumes) and its time
measured. RSS (``/proc/self/statm``) and the per-window time are recorded at intervals.

Usage::

    python tools/soak.py                     # 1 hour of data (about 10-20 min wall on 1 core)
    python tools/soak.py --duration 300      # 5 min variant

Prints a table: data time, frames, RSS (MB), window align time (ms, mean of the interval),
decode rate (frames/s). Flat RSS and flat window time are the target.
"""
from __future__ import annotations

import argparse
import os
import time
from typing import Sequence

from estimator.decode.listener import DecodeListener
from firmware_sim.faults import FaultConfig
from firmware_sim.node import NodeConfig, SensorNode


def rss_mb() -> float:
    """Resident set size of this process (MB)."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6


def soak(duration: float = 3600.0, window: float = 10.0, step: float = 1.0,
         capacity: int = 1 << 14, report_every: float = 300.0,
         loss: float = 0.02) -> list[dict[str, float]]:
    """Run the soak; one record per ``report_every`` seconds of data.

    Returns
    -------
    list of dict
        ``t`` (data s), ``frames``, ``rss_mb``, ``window_ms`` (mean), ``window_ms_max``,
        ``frames_per_s`` (decode + align wall rate over the interval).
    """
    cfg = NodeConfig(model="quarter2", scenario="random", duration=duration, speed=0.0,
                     channels=["x1", "x2", "x1_dot", "x2_dot", "r", "r_dot"],
                     faults=FaultConfig(loss=loss))
    node = SensorNode(cfg)
    lst = DecodeListener("quarter2", node.db, capacity=capacity)
    on = lst.on_message_received
    rows: list[dict[str, float]] = []
    next_win, next_rep = window, report_every
    win_times: list[float] = []
    n = 0
    n_rep = 0
    wall_rep = time.perf_counter()
    for msg in node.frames():
        on(msg)
        n += 1
        t = msg.timestamp
        if t >= next_win:
            t0 = time.perf_counter()
            lst.aligned(window=window)
            win_times.append(time.perf_counter() - t0)
            next_win += step
        if t >= next_rep:
            now = time.perf_counter()
            rows.append({"t": t, "frames": n, "rss_mb": rss_mb(),
                         "window_ms": 1e3 * sum(win_times) / max(len(win_times), 1),
                         "window_ms_max": 1e3 * max(win_times, default=0.0),
                         "frames_per_s": (n - n_rep) / (now - wall_rep)})
            win_times.clear()
            n_rep, wall_rep = n, now
            next_rep += report_every
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    """Command line of the tool."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=3600.0, help="data seconds (default 3600)")
    ap.add_argument("--window", type=float, default=10.0, help="window length s (default 10)")
    ap.add_argument("--step", type=float, default=1.0, help="window step s (default 1)")
    ap.add_argument("--every", type=float, default=None,
                    help="report interval s of data (default duration/12)")
    ap.add_argument("--capacity", type=int, default=1 << 14, help="ring rows per message")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = soak(a.duration, a.window, a.step, a.capacity, a.every or a.duration / 12)
    print(f"soak: quarter2 random road, 500 Hz, 2 % loss, {a.duration:g} s of data, window "
          f"{a.window:g} s every {a.step:g} s, ring {a.capacity} rows; wall "
          f"{time.perf_counter() - t0:.0f} s")
    print("| data t (s) | frames | RSS (MB) | window align mean (ms) | max (ms) | frames/s |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['t']:.0f} | {r['frames']:.0f} | {r['rss_mb']:.1f} | {r['window_ms']:.2f} | "
              f"{r['window_ms_max']:.2f} | {r['frames_per_s']:.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
