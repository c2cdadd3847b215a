"""End to end: simulated sensor node -> python-can virtual bus -> suspid monitor -> alert frame."""
from __future__ import annotations

import json
import os
import threading
import time

import can
import pytest

from firmware_sim.node import NodeConfig, SensorNode
from firmware_sim.transport import open_bus
from suspid.can.codec import decode_alert
from suspid.can.dbc import load_dbc
from suspid.cli import main
from tests.conftest import write_config

#: the node paced at x6 on a live bus, the monitor keeping up in wall-clock time
pytestmark = pytest.mark.realtime

FIX = ["--fix", "m1=300", "--fix", "m2=40", "--fix", "c2=300", "--fix", "k2=200000"]


def test_node_virtual_bus_monitor_alert(capsys, tmp_path) -> None:
    ch = f"suspid-e2e-{os.getpid()}"
    # damper-wear: c1 falls linearly from 1500 N s/m at 5 s towards 5 % at 120 s, crossing
    # 70 % of nominal at 41.3 s. The node runs, and lingers on the bus after its last sample,
    # until a bus participant has seen the alert frame, so the node receives the alert even
    # when the monitor lags behind the node on a busy machine.
    cfg = NodeConfig(model="quarter2", scenario="damper-wear", duration=120.0, wear_start=5.0,
                     wear_to=0.05, seed=2)
    node = SensorNode(cfg)
    crossing = 5.0 + 0.3 / 0.95 * 115.0
    assert abs(node.truth(crossing)["c1"] - 1050.0) < 1.0
    node_bus = open_bus("virtual", ch)
    spy = can.Bus(interface="virtual", channel=ch)  # a third node on the bus: sees the alert frame
    db = load_dbc()
    aid = db.get_message_by_name("SUSPID_Alert").frame_id
    summary: dict = {}
    seen: list = []
    stop = threading.Event()

    def run_node() -> None:
        time.sleep(1.5)  # let the monitor attach first
        summary["node"] = node.run(node_bus, speed=6.0, stop=stop, linger=30.0)

    def watch() -> None:
        while not stop.is_set():
            m = spy.recv(0.2)
            if m is not None and m.arbitration_id == aid:
                seen.append(decode_alert(db, m.data))
                if seen[-1]["severity"] != "forecast":
                    time.sleep(1.0)  # let the node's rx task pick it up too
                    stop.set()

    th = threading.Thread(target=run_node, daemon=True)
    wt = threading.Thread(target=watch, daemon=True)
    th.start()
    wt.start()
    afile = tmp_path / "alerts.jsonl"
    try:
        rc = main(["monitor", "--model", "quarter2", "--interface", "virtual", "--channel", ch,
                   *FIX, "--jsonl", "--config",
                   write_config(tmp_path, "[live]\nidle_timeout_s = 3\n"), "--alert-file", str(afile)])
        th.join(60)
    finally:
        stop.set()
        wt.join(5)
        node_bus.shutdown()
        spy.shutdown()
    assert rc == 0
    out = [json.loads(l) for l in capsys.readouterr().out.splitlines() if l.startswith("{")]
    est = [o for o in out if o["type"] == "estimate"]
    alerts = [o for o in out if o["type"] == "alert"]
    assert len(est) >= 20
    assert out[-1]["type"] == "summary" and out[-1]["frames"]["accepted"] > 60_000
    assert [o["t"] for o in est[:3]] == pytest.approx([3.0, 4.5, 6.0], abs=0.01)
    # data time from the node's sample ticks: windows end every 1.5 s of node time
    assert est[0]["t"] == pytest.approx(3.0, abs=0.01)
    assert [a["parameter"] for a in alerts] == ["c1"]
    assert crossing < alerts[0]["t"] < crossing + 8.0
    # the alert went out as the DBC frame: the node and a third bus participant received it
    # a forecast frame (severity "forecast") came before the alert frame
    assert [(s["parameter"], s["severity"]) for s in seen][-1] == ("c1", "warning")
    assert {s["severity"] for s in seen[:-1]} <= {"forecast"}
    forecasts = [o for o in out if o["type"] == "forecast"]
    assert forecasts and forecasts[0]["t"] < crossing
    assert forecasts[0]["crossing_t_low"] <= crossing <= forecasts[0]["crossing_t_high"]
    assert [a["parameter"] for a in summary["node"].alerts][-1] == "c1"
    logged = [json.loads(l) for l in afile.read_text().splitlines()]
    assert [l["type"] for l in logged if l["type"] == "alert"] == ["alert"]
