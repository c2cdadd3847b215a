"""Transports: the SLCAN pty adapter (in-process and two processes), socketcan."""
from __future__ import annotations

import json
import math
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import can
import numpy as np
import pytest
import serial

from estimator.decode import DecodeListener
from firmware_sim.transport import BufferedSlcanBus, SlcanPtyBus, open_bus
from suspid.can.codec import encode_alert
from suspid.can.dbc import load_dbc
from tests.conftest import start_slcan_node, suspid_env, write_config

REPO = Path(__file__).resolve().parents[2]

#: pty adapters read by threads with short timeouts, nodes paced with --speed
pytestmark = pytest.mark.realtime


def _ask(port: serial.Serial, cmd: bytes) -> bytes:
    port.write(cmd + b"\r")
    out = b""
    deadline = time.monotonic() + 2
    while not out.endswith((b"\r", b"\a")) and time.monotonic() < deadline:
        out += port.read(1)
    return out


def test_slcan_adapter_protocol():
    bus = SlcanPtyBus()
    try:
        with serial.Serial(bus.path, timeout=0.5) as port:
            assert _ask(port, b"V") == b"V1013\r"
            assert _ask(port, b"N") == b"NSUSP\r"
            assert _ask(port, b"S6") == b"\r" and bus.bitrate == 500000
            assert _ask(port, b"SX") == b"\a"
            assert _ask(port, b"X") == b"\a"
            bus.send(can.Message(arbitration_id=0x123, is_extended_id=False, data=b"\x01"))  # closed: dropped
            assert bus.dropped_closed == 1
            assert _ask(port, b"O") == b"\r" and bus.wait_open(1)
            assert _ask(port, b"S4") == b"\a"  # no bitrate change while open
            bus.send(can.Message(arbitration_id=0x123, is_extended_id=False, data=b"\x01\xAB"))
            bus.send(can.Message(arbitration_id=0x1ABCDEF, is_extended_id=True, data=b""))
            assert port.read(10) == b"t123201AB\r"
            assert port.read(11) == b"T01ABCDEF0\r"
            assert _ask(port, b"t7DF3112233") == b"z\r"
            msg = bus.recv(1.0)
            assert msg.arbitration_id == 0x7DF and bytes(msg.data) == b"\x11\x22\x33"
            assert _ask(port, b"Z1") == b"\r"
            bus.send(can.Message(arbitration_id=0x10, is_extended_id=False, data=b"", timestamp=61.5))
            assert port.read(10) == b"t010005DC\r"  # 61.5 s -> 1500 ms mod 60000
            assert _ask(port, b"C") == b"\r" and not bus.is_open
    finally:
        bus.shutdown()


def test_slcan_pty_in_process_with_buffered_client():
    db = load_dbc()
    node_bus = open_bus("slcan", "pty")
    try:
        # suspid's own opener: python-can's slcan protocol with chunked reads
        host = open_bus("slcan", node_bus.path, sleep_after_open=0, bitrate=500000)
        assert isinstance(host, BufferedSlcanBus)
        assert node_bus.wait_open(2) and host.get_version(1.0) == (10, 13)
        lst = DecodeListener("quarter2", db, time_source="tick")
        notifier = can.Notifier(host, [lst])
        from firmware_sim.node import NodeConfig, SensorNode

        node = SensorNode(NodeConfig(scenario="bump", duration=0.5, rate=500), db)
        host.send(encode_alert(db, "quarter2", "c1", 1000.0, 1500.0))
        summary = node.run(node_bus, speed=0)
        assert node_bus.drain(5)
        time.sleep(0.2)
        notifier.stop()
        host.shutdown()
    finally:
        node_bus.shutdown()
    assert lst.counts.accepted == summary.frames_sent == 4 * 251 + 7
    assert sum(lst.counts.rejected.values()) == 0 and node_bus.overflows == 0
    assert [a["parameter"] for a in summary.alerts] == ["c1"]
    np.testing.assert_allclose(lst.aligned().t, np.arange(251) / 500.0, atol=1e-12)


def test_slcan_adapter_timestamps_give_the_frame_times():
    """``timestamps=True``: the host switches the adapter to Lawicel timestamp mode (``Z1``)
    and takes each frame's time from the adapter (the simulated node stamps its data time),
    not from its own arrival clock; without it, host arrival times."""
    from firmware_sim.node import NodeConfig, SensorNode
    from suspid.can.bus import adapter_ms

    assert adapter_ms("t1108" + "00" * 8 + "EA5F\r") == 0xEA5F
    assert adapter_ms("t1102ABCD\r") is None and adapter_ms("r1230" + "0010") == 0x10
    db = load_dbc()
    node_bus = open_bus("slcan", "pty")
    try:
        host = open_bus("slcan", node_bus.path, sleep_after_open=0, timestamps=True)
        assert isinstance(host, BufferedSlcanBus)
        assert node_bus.wait_open(5)
        # the host's Z1 may reach the adapter just after its O: wait for it (loaded machine)
        deadline = time.monotonic() + 5.0
        while not node_bus.timestamps and time.monotonic() < deadline:
            time.sleep(0.01)
        assert node_bus.timestamps
        got: list[can.Message] = []
        notifier = can.Notifier(host, [got.append])
        SensorNode(NodeConfig(scenario="bump", duration=0.5, rate=500), db).run(node_bus, speed=0)
        assert node_bus.drain(5)
        time.sleep(0.2)
        notifier.stop()
        host.shutdown()
    finally:
        node_bus.shutdown()
    sync = np.array([m.timestamp for m in got if m.arbitration_id == 0x100])
    assert sync.size == 251 and host.adapter_timed == len(got) and host.host_timed == 0
    # the node ran as fast as possible (--speed max): arrival times are bunched, the
    # adapter's times are the 2 ms sample ticks (to its 1 ms resolution)
    np.testing.assert_allclose(np.diff(sync), 0.002, atol=1.001e-3)
    assert sync[-1] - sync[0] == pytest.approx(0.5, abs=1.001e-3)


def test_two_process_slcan_link(tmp_path):
    """``suspid node --interface slcan --channel pty`` in a subprocess; python-can slcan here."""
    config = write_config(tmp_path, "[node]\nopen_timeout_s = 20\n")
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen(
        [sys.executable, "-m", "suspid", "node", "--scenario", "bump", "--interface", "slcan",
         "--channel", "pty", "--duration", "1.0", "--speed", "4", "--config", config],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=REPO)
    try:
        first = proc.stdout.readline()
        assert first.startswith("pty: /dev/"), first + proc.stderr.read()
        path = first.split(":", 1)[1].strip()
        db = load_dbc()
        lst = DecodeListener("quarter2", db, time_source="tick")
        with can.Bus(interface="slcan", channel=path, sleep_after_open=0) as host:
            notifier = can.Notifier(host, [lst], timeout=0.05)
            time.sleep(0.3)
            host.send(encode_alert(db, "quarter2", "c1", 950.0, 1500.0))
            deadline = time.monotonic() + 30
            while lst.node_status.get("state") != 4 and time.monotonic() < deadline:
                time.sleep(0.02)  # the node's last SN_Status says "stopping"
            notifier.stop()
        out, err = proc.communicate(timeout=30)  # the host closed: the node exits at once
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    summary = json.loads(out.strip().splitlines()[-1])
    node = summary["node"]
    assert summary["slcan"]["overflows"] == 0 and summary["slcan"]["host_frames"] == 1
    assert [a["parameter"] for a in node["alerts"]] == ["c1"]
    assert lst.counts.accepted == node["frames_sent"] == 4 * 501 + 12
    assert sum(lst.counts.rejected.values()) == 0
    al = lst.aligned()
    np.testing.assert_allclose(al.t, np.arange(501) / 500.0, atol=1e-12)
    assert np.nanmax(al.values["r"]) == pytest.approx(0.1, abs=1e-3)  # the bump went through


def _af_can_unavailable() -> str | None:
    if not hasattr(socket, "AF_CAN"):
        return "this Python has no socket.AF_CAN"
    try:
        s = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    except OSError as exc:
        return f"kernel has no SocketCAN (AF_CAN socket: {exc.strerror})"
    s.close()
    if not Path("/sys/class/net/vcan0").exists():
        return "no vcan0 interface (run tools/setup_vcan.sh as root)"
    return None


@pytest.mark.socketcan
@pytest.mark.skipif(_af_can_unavailable() is not None, reason=str(_af_can_unavailable()))
def test_socketcan_vcan0_same_code_path():
    from firmware_sim.node import NodeConfig, SensorNode

    db = load_dbc()
    lst = DecodeListener("quarter2", db, time_source="tick")
    with open_bus("socketcan", "vcan0") as rx, open_bus("socketcan", "vcan0") as tx:
        notifier = can.Notifier(rx, [lst])
        summary = SensorNode(NodeConfig(scenario="bump", duration=0.5), db).run(tx, speed=0)
        time.sleep(0.3)
        notifier.stop()
    assert lst.counts.accepted == summary.frames_sent


def test_socketcan_unavailable_is_a_clear_usage_error():
    if _af_can_unavailable() is None:
        pytest.skip("SocketCAN is available here; the error path cannot be shown")
    from suspid.errors import UsageError

    with pytest.raises(UsageError, match="cannot open CAN interface 'socketcan' channel 'vcan0'"):
        open_bus("socketcan", "vcan0")


def test_two_process_node_and_monitor_cli_over_slcan(tmp_path):
    """The contract's pair: ``suspid node --interface slcan --channel pty`` and
    ``suspid monitor --interface slcan --channel /dev/pts/N`` as two processes.

    The monitor estimates window by window, sends its alert frame back to the node, and
    ends cleanly (exit 0, summary line) when the node closes its pty -- it once died with a
    ``CanOperationError`` traceback there.
    """
    env = suspid_env()
    pty = write_config(tmp_path, "[node]\nopen_timeout_s = 30\nlinger_s = 1\n", "node.toml")
    node, path = start_slcan_node("--scenario", "damper-wear", "--duration", "24", "--speed", "4",
                                  "--config", pty)
    mon = None
    try:
        mon = subprocess.run(
            [sys.executable, "-m", "suspid", "monitor", "--model", "quarter2", "--interface", "slcan",
             "--channel", path, "--fix", "m1=300", "--fix", "m2=40", "--fix", "c2=300",
             "--fix", "k2=200000", "--nominal", "c1=1500", "--nominal", "k1=20000",
             "--config", write_config(tmp_path, "[live]\nidle_timeout_s = 30\n"), "--jsonl"],
            capture_output=True, text=True, env=env, cwd=REPO, timeout=180)
        out, err = node.communicate(timeout=60)
    finally:
        if node.poll() is None:
            node.kill()
    assert mon.returncode == 0, mon.stderr
    assert "Traceback" not in mon.stderr
    lines = [json.loads(l) for l in mon.stdout.splitlines() if l.strip()]
    est = [d for d in lines if d["type"] == "estimate"]
    summary = lines[-1]
    assert summary["type"] == "summary"
    assert summary["stopped"].startswith("bus closed"), summary["stopped"]
    assert len(est) >= 10
    assert summary["frames"]["accepted"] > 0.95 * 4 * 500 * 24
    c1 = [d["params"]["c1"] for d in est]
    assert c1[0] == pytest.approx(1500, rel=0.05)      # the damper wears from t = 20 s on
    assert node.returncode == 0, err


def _slcan_monitor(tmp_path: Path, live: str = "", duration: float = 3.0) -> dict:
    """``suspid node`` at half real time over the pty adapter and ``suspid monitor`` on it
    with the ``[live]`` settings ``time_source = "timestamp"`` and ``live``; the monitor's
    summary line."""
    config = write_config(tmp_path, '[live]\ntime_source = "timestamp"\nidle_timeout_s = 30\n'
                                    f"alert_frames = false\n{live}", f"live{len(live)}.toml")
    pty = write_config(tmp_path, "[node]\nopen_timeout_s = 60\nlinger_s = 1\n", "node.toml")
    node, path = start_slcan_node("--scenario", "random", "--duration", str(duration),
                                  "--speed", "0.5", "--config", pty)
    try:
        mon = subprocess.run(
            [sys.executable, "-m", "suspid", "monitor", "--model", "quarter2", "--interface",
             "slcan", "--channel", path, "--config", config, "--fix",
             "m1=300", "--fix", "m2=40", "--fix", "c2=300", "--fix", "k2=200000",
             "--window", "1", "--step", "0.5", "--jsonl"],
            capture_output=True, text=True, env=suspid_env(), cwd=REPO,
            timeout=300)
        node.communicate(timeout=60)
    finally:
        if node.poll() is None:
            node.kill()
    assert mon.returncode == 0, mon.stderr
    lines = [json.loads(x) for x in mon.stdout.splitlines() if x.strip()]
    assert lines[-1]["type"] == "summary"
    return {"summary": lines[-1], "estimates": [d for d in lines if d["type"] == "estimate"]}


def test_monitor_cli_slcan_timestamps_time_frames_by_the_adapter(tmp_path):
    """``[live] slcan_timestamps = true``: the frames' times are the adapter's (Lawicel ``Z1``).

    The node runs at half real time and its adapter stamps the node's data time, so the
    adapter's clock runs at half the host's: 3 s of data take 6 s to arrive. Timed by the
    adapter the monitor sees 3 s of data (5 windows of 1 s every 0.5 s, exactly 0.5 s
    apart); timed by the host (without the flag) 6 s.
    """
    a = _slcan_monitor(tmp_path, "slcan_timestamps = true\n")
    s = a["summary"]
    rx = s["frames"]["receive"]
    assert s["frames"]["time_base"] == "timestamp"
    assert rx["adapter_timed"] == rx["read"] == s["frames"]["accepted"] > 0
    assert rx["host_timed"] == 0
    assert s["data_s"] == pytest.approx(3.0, abs=0.005)
    t = np.array([d["t"] for d in a["estimates"]])
    assert t.size == 5
    np.testing.assert_allclose(np.diff(t), 0.5, atol=1e-6)

    h = _slcan_monitor(tmp_path)
    s = h["summary"]
    rx = s["frames"]["receive"]
    assert rx["host_timed"] == rx["read"] == s["frames"]["accepted"] > 0
    assert rx["adapter_timed"] == 0
    assert s["data_s"] > 5.0              # the host's clock: about twice the adapter's
    assert s["windows_cut"] >= 9


def test_monitor_cli_slcan_timestamps_needs_slcan(tmp_path):
    config = write_config(tmp_path, "[live]\nslcan_timestamps = true\nidle_timeout_s = 1\n")
    out = subprocess.run([sys.executable, "-m", "suspid", "monitor", "--model", "quarter2",
                          "--interface", "virtual", "--channel", "ts-flag", "--config", config],
                         capture_output=True, text=True, env=suspid_env(), cwd=REPO, timeout=120)
    assert out.returncode == 2
    assert out.stderr.strip().splitlines()[-1] == \
        "error: --interface: live.slcan_timestamps needs --interface slcan, got virtual"


def test_monitor_cli_rx_buffer_is_seconds_of_the_dbc_frame_rate(tmp_path):
    """``[live] rx_buffer_s = 0.5``: the receiver holds 0.5 s at suspid's DBC rate (every message at
    its ``GenMsgCycleTime``: 14,010 frames/s); a live bus other than SocketCAN reports its
    socket overrun as unknown (null)."""
    rate = sum(1000.0 / m.cycle_time for m in load_dbc().messages if m.cycle_time)
    assert rate == pytest.approx(14_010)
    out = subprocess.run([sys.executable, "-m", "suspid", "monitor", "--model", "quarter2",
                          "--interface", "virtual", "--channel", "rx-buffer-flag", "--config",
                          write_config(tmp_path, "[live]\nrx_buffer_s = 0.5\nidle_timeout_s = 0.5\n"),
                          "--jsonl"],
                         capture_output=True, text=True, env=suspid_env(), cwd=REPO, timeout=120)
    assert out.returncode == 0, out.stderr
    rx = json.loads(out.stdout.splitlines()[-1])["frames"]["receive"]
    assert rx["buffer_capacity"] == math.ceil(0.5 * rate) and rx["read"] == 0
    assert rx["socket_overrun"] is None and rx["lost_by_cause"]["socket_overrun"] is None
    zero = write_config(tmp_path, "[live]\nrx_buffer_s = 0\n", "zero.toml")
    bad = subprocess.run([sys.executable, "-m", "suspid", "monitor", "--model", "quarter2",
                          "--interface", "virtual", "--channel", "x", "--config", zero],
                         capture_output=True, text=True, env=suspid_env(), cwd=REPO, timeout=120)
    assert bad.returncode == 2
    assert bad.stderr == (f"error: {zero}: live.rx_buffer_s: expected a number > 0 (s), got 0 "
                          "(integer)\n")
