"""Live receive path at a saturated vcan0: CPU share and lost frames, with a slow fit.

Run with vcan0 up (natively, or under User-Mode Linux)::

    tools/vcan_bench.sh .venv/bin/python tools/bench_vcan.py [--duration 10] [--fit-s 1.5]
        [--fit-kind sleep|cpu] [--rx-buffer SECONDS]

Next to ``suspid node --interface socketcan --channel vcan0`` (500 Hz quarter car, 4
messages per sample) ``cangen`` fills the bus with foreign frames (``--gap-ms``, default about a saturated
1 Mbit/s bus), and
``candump`` records everything. This process receives with the monitor's live path
(:func:`estimator.stream.drivers.run_bus`: a receiver thread into a bounded buffer, the
decoder, the window cutter) while each window's "fit" deliberately takes ``--fit-s`` of
wall time -- longer than the window step: sleeping (``--fit-kind sleep``, a fit in compiled
code that lets the receiver thread run) or spinning in Python (``cpu``, a fit that holds
the interpreter lock as a pure-Python optimiser would). Printed side by side: frames
candump saw, frames the live path received, node frames accepted, lost frames by cause
(receiver buffer overflow, kernel socket overrun, bus error frames, counter gaps and the
loss each followed), the receiver buffer's peak, and the live path's CPU share of one core.
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from estimator.decode import DecodeListener
from estimator.stream.drivers import CanWindowDriver, LiveStop, bus_frame_rate, run_bus
from suspid.can.bus import open_bus
from estimator.stream.drivers import RECEIVE_BUFFER_S

REPO = Path(__file__).resolve().parents[1]


def _receivers() -> int:
    try:
        text = Path("/proc/net/can/rcvlist_all").read_text()
    except OSError:
        return 0
    return sum(1 for line in text.splitlines() if line.split()[:1] == ["vcan0"])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=10.0, help="node run (s of data)")
    ap.add_argument("--fit-s", type=float, default=1.5, help="wall time of each window's fit")
    ap.add_argument("--fit-kind", choices=["sleep", "cpu"], default="sleep",
                    help="the slow fit sleeps (default) or spins in Python holding the GIL")
    ap.add_argument("--rx-buffer", type=float, default=RECEIVE_BUFFER_S,
                    help=f"receiver buffer, s of data at the DBC's frame rate (default {RECEIVE_BUFFER_S:g})")
    ap.add_argument("--window", type=float, default=2.0)
    ap.add_argument("--step", type=float, default=1.0)
    ap.add_argument("--gap-ms", type=float, default=0.12,
                    help="cangen gap (ms); 0.12 ms ~ 8 k frames/s, a saturated 1 Mbit/s bus")
    ap.add_argument("--timeout", type=float, default=300.0, help="give up after (s of wall)")
    args = ap.parse_args()
    for tool in ("candump", "cangen"):
        if shutil.which(tool) is None:
            print(f"error: {tool} missing (apt-get install can-utils)", file=sys.stderr)
            return 2
    tmp = Path(tempfile.mkdtemp(prefix="bench-vcan-"))
    windows = []

    def slow_fit(t: Any, data: Any) -> None:
        if args.fit_kind == "sleep":
            time.sleep(args.fit_s)
        else:
            end = time.monotonic() + args.fit_s
            x = 0
            while time.monotonic() < end:
                for _ in range(1000):
                    x += 1
        windows.append(float(t[-1]))

    lst = DecodeListener("quarter2", capacity=1 << 15, time_source="auto")
    drv = CanWindowDriver(lst, args.window, args.step, slow_fit)
    bus = open_bus("socketcan", "vcan0")
    before = _receivers()
    dump = subprocess.Popen(["candump", "-L", "-r", str(8 << 20), "vcan0"],
                            stdout=(tmp / "candump.log").open("wb"))
    while _receivers() <= before:
        time.sleep(0.02)
    gen = subprocess.Popen(["cangen", "vcan0", "-g", f"{args.gap_ms:g}", "-I", "7FF", "-L", "8"])
    node = subprocess.Popen([sys.executable, "-m", "suspid", "node", "--scenario", "random",
                             "--duration", str(args.duration), "--interface", "socketcan",
                             "--channel", "vcan0"], stdout=subprocess.PIPE, cwd=REPO)
    stop = LiveStop(idle_timeout=None)
    cpu0, wall0 = time.process_time(), time.monotonic()

    def ended() -> bool:
        return node.poll() is not None

    # stop 1 s after the node ends: run_bus polls ``stop.stop``
    def watch() -> None:
        try:
            node.wait(timeout=args.timeout)
        except subprocess.TimeoutExpired:
            node.kill()
        time.sleep(1.0)
        gen.terminate()
        time.sleep(0.5)
        stop.stop = True
        stop.reason = "node ended"

    threading.Thread(target=watch, daemon=True).start()
    received = run_bus(drv, bus, stop, buffer_s=args.rx_buffer)
    cpu, wall = time.process_time() - cpu0, time.monotonic() - wall0
    gen.wait(timeout=10)
    time.sleep(0.3)
    dump.terminate()
    dump.wait(timeout=10)
    bus.shutdown()
    seen = sum(1 for _ in (tmp / "candump.log").open())
    f = lst.frame_stats()
    rx = f.get("receive", {})
    node_out = node.stdout.read().decode() if node.stdout else ""
    sent = int(node_out.split('"frames_sent": ')[1].split(",")[0]) if "frames_sent" in node_out \
        else -1
    print(f"{'frames candump saw':34s} {seen:>10d}")
    print(f"{'frames the live path received':34s} {received:>10d}   "
          f"({received / max(seen, 1):.4f} of candump's)")
    print(f"{'node frames sent / accepted':34s} {sent:>10d} / {f['accepted']}")
    print(f"{'foreign frames (unknown_id)':34s} {f['rejected']['unknown_id']:>10d}")
    after = rx.get("counter_gap_after", {})
    errors = rx.get("bus_errors") or {}
    print(f"{'lost: receiver buffer overflow':34s} {rx.get('buffer_overflow', 0):>10d}")
    print(f"{'lost: kernel socket overrun':34s} {rx.get('socket_overrun')!s:>10s}")
    print(f"{'bus error frames':34s} {rx.get('error_frames', 0):>10d}   "
          f"{' '.join(f'{k}={v}' for k, v in errors.items())}")
    print(f"{'counter gaps (node frames missing)':34s} {rx.get('counter_gap', 0):>10d}   "
          f"(after overrun {after.get('socket_overrun', 0)}, bus error {after.get('bus', 0)}, "
          f"buffer overflow {after.get('buffer_overflow', 0)}, none {after.get('none', 0)})")
    cap = rx.get("buffer_capacity", 0)
    rate = bus_frame_rate(lst.db)
    print(f"{'receiver buffer peak / capacity':34s} {rx.get('max_queued', 0):>10d} / {cap}   "
          f"({args.rx_buffer:g} s at {rate:.0f} frames/s; peak {rx.get('max_queued', 0) / max(cap, 1):.2f})")
    print(f"{'kernel socket queue (bytes)':34s} {rx.get('socket_rcvbuf', 0):>10d}")
    print(f"{'windows fitted ({} fit {:.2f} s, step {:.2f} s)'.format(args.fit_kind, args.fit_s, args.step):34s} "
          f"{len(windows):>10d}")
    print(f"{'live path CPU share of one core':34s} {cpu / wall:>10.3f}   "
          f"({cpu:.2f} s CPU in {wall:.2f} s, sleeping fits included in wall)")
    print(f"{'time base':34s} {f['time_base']:>10s}")
    lost = rx.get("lost_by_cause", {})
    return 0 if received == seen and not any(lost.values()) and ended() else 1


if __name__ == "__main__":
    sys.exit(main())
