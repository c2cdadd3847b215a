"""The main job's demo (README): sensor node -> in-process virtual CAN bus -> estimator.

1. The simulated sensor node (``firmware_sim``) runs the ``damper-wear`` scenario — the
   front damper's c1 wears from 1500 N s/m (from t = 20 s) down to 50 % at 60 s — and
   sends its E2E-protected frames on a python-can ``virtual`` bus (in-process: node and
   estimator are threads).
2. ``suspid monitor`` on the same bus decodes and validates the frames, identifies
   c1 and k1 window by window (Nelder–Mead, warm-started, bounded budget), and raises a
   maintenance alert when c1 is confidently below 70 % of nominal: a JSON line, a line in a
   durable alert file, and the DBC alert frame back on the bus.
3. ``suspid compare`` runs the sliding-window identifier and the filterpy EKF baseline on
   the same stream and plots both c1 tracks against the truth.
"""
from __future__ import annotations

import contextlib
import io
import json
import os
import sys
import threading
import time
from pathlib import Path

FIX = ["--fix", "m1=300", "--fix", "m2=40", "--fix", "c2=300", "--fix", "k2=200000"]
DURATION, WEAR_START, WEAR_TO = 60.0, 20.0, 0.5  # as suspid compare's damper-wear defaults


def run_cli(args: list[str]) -> str:
    """Run one ``suspid`` command in-process and return what it printed."""
    from suspid.cli import main

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main(args)
    if rc != 0:
        raise SystemExit(f"suspid {args[0]} failed with exit status {rc}")
    return buf.getvalue()


def live_monitor(out: Path) -> tuple[list[dict], dict, float]:
    """Node thread + monitor on one virtual bus; returns (events, node summary, crossing)."""
    from firmware_sim.node import NodeConfig, SensorNode
    from firmware_sim.transport import open_bus

    channel = f"suspid-demo-{os.getpid()}"
    # the sensors of a production car: body acceleration and ride height, never the road
    node = SensorNode(NodeConfig(model="quarter2", scenario="damper-wear", duration=DURATION,
                                 wear_start=WEAR_START, wear_to=WEAR_TO, seed=1,
                                 channels=["production"]))
    crossing = WEAR_START + 0.3 / (1 - WEAR_TO) * (DURATION - WEAR_START)
    node_bus = open_bus("virtual", channel)
    summary: dict = {}
    # the node keeps its receive task running after its last frame until the monitor has
    # finished: the monitor's alert and forecast frames go out when its windows are fitted,
    # which may be seconds after the node at 8x real time has sent everything
    monitor_done = threading.Event()

    def run_node() -> None:
        # start sending once the monitor has attached to the virtual channel (python-can's
        # virtual bus delivers only to buses that exist when a frame is sent)
        from can.interfaces import virtual

        deadline = time.monotonic() + 60.0
        while len(virtual.channels.get(channel, ())) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)
        summary["node"] = node.run(node_bus, speed=8.0, linger=120.0, linger_until=monitor_done)

    th = threading.Thread(target=run_node, daemon=True)
    th.start()
    alert_file = out / "alerts.jsonl"
    alert_file.unlink(missing_ok=True)
    # the live bus: stop 3 s after the node's last frame (docs/configuration.md)
    config = out / "live.toml"
    config.write_text("[live]\nidle_timeout_s = 3\n")
    try:
        text = run_cli(["monitor", "--model", "quarter2", "--interface", "virtual", "--channel",
                        channel, *FIX, "--road", "unknown", "--jsonl", "--config", str(config),
                        "--alert-file", str(alert_file)])
        monitor_done.set()
        th.join(30)
    finally:
        node_bus.shutdown()
    (out / "monitor.jsonl").write_text(text)
    events = [json.loads(ln) for ln in text.splitlines() if ln.startswith("{")]
    return events, summary.get("node"), crossing


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    w = sys.stdout.write
    w(f"1) sensor node (body acceleration + ride height, no road) -> virtual CAN bus -> "
      f"suspid monitor --road unknown ({DURATION:.0f} s of data at 8x real time)\n")
    events, node_summary, crossing = live_monitor(out)
    est = [e for e in events if e["type"] == "estimate"]
    alerts = [e for e in events if e["type"] == "alert"]
    summ = next((e for e in events if e["type"] == "summary"), {})
    w(f"   frames accepted {summ.get('frames', {}).get('accepted', '?')}, "
      f"windows identified {len(est)}\n")
    for e in (est[0], est[len(est) // 2], est[-1]) if est else ():
        c1, k1 = e["params"]["c1"], e["params"]["k1"]
        w(f"   t = {e['t']:5.1f} s   c1 = {c1:7.1f} ± {e['stderr'].get('c1', float('nan')):5.1f} N s/m"
          f"   k1 = {k1:8.0f} ± {e['stderr'].get('k1', float('nan')):4.0f} N/m\n")
    w(f"   c1 truly crosses 70 % of nominal at t = {crossing:.1f} s\n")
    forecasts = [e for e in events if e["type"] == "forecast"]
    if forecasts:
        f = forecasts[0]
        w(f"   FORECAST t = {f['t']:.1f} s: {f['message']}\n")
    for a in alerts:
        w(f"   ALERT t = {a['t']:.1f} s: {a['message']}\n")
    if node_summary is not None and getattr(node_summary, "alerts", None):
        frames = node_summary.alerts
        nf = sum(1 for a in frames if a.get("severity") == "forecast")
        w(f"   the node received {len(frames) - nf} alert and {nf} forecast frame(s) on the bus\n")
    w(f"   JSON lines: {out / 'monitor.jsonl'}, durable alerts: {out / 'alerts.jsonl'}\n\n")

    w("2) sliding-window Nelder–Mead vs filterpy EKF on the same stream (suspid compare)\n")
    cmp = json.loads(run_cli(["compare", "--model", "quarter2", "--scenario", "damper-wear",
                              "--duration", str(DURATION), "--wear-to", str(WEAR_TO), *FIX,
                              "--road", "unknown",
                              "--plot", str(out / "compare-c1.png"), "--json"]))
    w(f"   {'':22}{'Nelder-Mead':>14}{'EKF':>12}\n")
    nm, ekf = cmp["nm"], cmp["ekf_result"]
    rows = [("c1 RMSE (% of truth)", lambda r: f"{r['params']['c1']['rmse_pct']:.2f}"),
            ("alert delay (s)", lambda r: f"{r['params']['c1']['alert_delay_s']:.1f}"
             if r["params"]["c1"]["alert_delay_s"] is not None else "none"),
            ("false alarms", lambda r: str(r["params"]["c1"]["false_alarms"])),
            ("first forecast lead (s)", lambda r: f"{r['params']['c1']['forecast_lead_s']:.1f}"
             if r["params"]["c1"].get("forecast_lead_s") is not None else "none"),
            ("CPU per sample (us)", lambda r: f"{r['cpu_us_per_sample']:.0f}")]
    for label, f in rows:
        w(f"   {label:22}{f(nm):>14}{f(ekf):>12}\n")
    w(f"   plot: {out / 'compare-c1.png'}\n")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/demo"))
