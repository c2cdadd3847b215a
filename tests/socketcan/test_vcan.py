"""suspid on a real kernel CAN stack (vcan0), with can-utils as the other end.

* ``suspid node`` -> vcan0 -> ``suspid monitor``, separate processes; ``candump`` records
  the bus, the alert frame included; the monitor receives every frame candump receives;
* ``canplayer`` replays the node's own log into vcan0: the live monitor's estimates equal
  ``suspid monitor --input`` on that log;
* ``canplayer`` and ``cangen`` inject foreign, malformed and out-of-sequence frames: each
  is counted under its reason and no valid frame is lost;
* the ``candump -L`` recording (wall-clock timestamps) is read back by identify, diagnose
  and monitor, on the sensor's clock;
* lost frames by cause: a stopped monitor whose kernel socket queue overflows under a
  ``cangen`` flood (socket overrun = frames candump saw minus frames received), error
  frames from ``cansend`` (a controller RX overflow, a bus-off), deliberate counter gaps:
  each lost frame is counted once, under its cause.

Run through ``tools/vcan_bench.sh`` where the host kernel has no SocketCAN.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

from firmware_sim.node import NodeConfig, SensorNode
from tests.conftest import REPO, suspid_env, write_config

pytestmark = pytest.mark.socketcan

MON_ARGS = ["--model", "quarter2", "--fix", "m1=300", "--fix", "m2=40", "--fix", "c2=300",
            "--fix", "k2=200000", "--nominal", "c1=1500", "--nominal", "k1=20000", "--jsonl"]
NODE_ARGS = ["--scenario", "damper-wear", "--duration", "24", "--wear-start", "4",
             "--wear-to", "0.3"]
ALERT_ID = 0x300


def _receivers() -> int:
    """CAN_RAW receivers registered on vcan0 (``/proc/net/can/rcvlist_all``)."""
    try:
        text = Path("/proc/net/can/rcvlist_all").read_text()
    except OSError:
        return 0
    return sum(1 for line in text.splitlines() if line.split()[:1] == ["vcan0"])


def _start(args: list[str], out: Path, wait_rx: bool = True) -> subprocess.Popen[bytes]:
    """Start a process writing stdout to ``out``; wait until it listens on vcan0."""
    before = _receivers()
    proc = subprocess.Popen(args, stdout=out.open("wb"), stderr=subprocess.PIPE,
                            env=suspid_env(), cwd=REPO)
    if wait_rx:
        deadline = time.monotonic() + 120
        while _receivers() <= before:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"{args[:4]} did not start listening on vcan0: "
                                   f"{proc.stderr.read().decode() if proc.stderr else ''}")
            time.sleep(0.05)
    return proc


def _stop(proc: subprocess.Popen[bytes], sig: int = signal.SIGINT) -> str:
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        _, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate()
    return (err or b"").decode()


def _suspid(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "suspid", *args], capture_output=True,
                          text=True, env=suspid_env(), cwd=REPO, timeout=timeout)


def _jsonl(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def _candump_ids(path: Path) -> Counter[int]:
    ids: Counter[int] = Counter()
    for line in path.read_text().splitlines():
        parts = line.split()
        if len(parts) >= 3 and "#" in parts[2]:
            ids[int(parts[2].split("#")[0], 16)] += 1
    return ids


def _config(tmp: Path, alert_frames: bool = True) -> list[str]:
    """``--config`` of a live monitor that never stops for silence (and, with
    ``alert_frames`` false, sends no alert frames)."""
    text = "[live]\nidle_timeout_s = 0\n" + ("" if alert_frames else "alert_frames = false\n")
    return ["--config", write_config(tmp, text, f"live-{alert_frames}.toml")]


def _live_monitor(tmp: Path, name: str, *extra: str,
                  alert_frames: bool = True) -> subprocess.Popen[bytes]:
    return _start([sys.executable, "-m", "suspid", "monitor", "--interface", "socketcan",
                   "--channel", "vcan0", *_config(tmp, alert_frames), *MON_ARGS, *extra],
                  tmp / name)


def _candump(tmp: Path, name: str) -> subprocess.Popen[bytes]:
    # -r: a larger socket queue, so candump itself keeps up on a slow guest
    return _start(["candump", "-L", "-r", str(8 << 20), "vcan0"], tmp / name)


@pytest.fixture(scope="module")
def node_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """node -> vcan0 -> monitor (separate processes), candump recording the bus."""
    tmp = tmp_path_factory.mktemp("vcan")
    dump = _candump(tmp, "candump.log")
    mon = _live_monitor(tmp, "monitor.jsonl")
    node = subprocess.run([sys.executable, "-m", "suspid", "node", *NODE_ARGS, "--interface",
                           "socketcan", "--channel", "vcan0", "--log", str(tmp / "node.log")],
                          capture_output=True, text=True, env=suspid_env(), cwd=REPO, timeout=600)
    time.sleep(2.0)   # the monitor's last windows and alert frame
    mon_err = _stop(mon)
    _settled(tmp / "candump.log")
    _stop(dump)
    return {"tmp": tmp, "node": node, "node_summary": json.loads(node.stdout.splitlines()[-1])["node"],
            "mon": mon, "mon_err": mon_err, "lines": _jsonl(tmp / "monitor.jsonl"),
            "candump": tmp / "candump.log", "node_log": tmp / "node.log"}


def test_node_to_monitor_with_alert_frame_on_the_bus(node_run: dict[str, Any]) -> None:
    assert node_run["node"].returncode == 0, node_run["node"].stderr
    assert node_run["mon"].returncode == 0, node_run["mon_err"]
    assert "Traceback" not in node_run["mon_err"]
    lines = node_run["lines"]
    summary = lines[-1]
    assert summary["type"] == "summary" and summary["stopped"] == "signal SIGINT"
    assert summary["frames"]["time_base"] == "tick"
    est = [d for d in lines if d["type"] == "estimate"]
    assert len(est) >= 8
    assert est[0]["params"]["c1"] == pytest.approx(1500, rel=0.1)
    assert any(d["type"] == "alert" and d["parameter"] == "c1" for d in lines), \
        [(d["type"], d.get("t"), d.get("params", {}).get("c1")) for d in lines]
    # candump saw the monitor's SUSPID_Alert frame on the bus
    ids = _candump_ids(node_run["candump"])
    assert ids[ALERT_ID] >= 1
    # the monitor received every frame candump received (its own alert frames aside), and
    # that is every frame the node sent
    sent = node_run["node_summary"]["frames_sent"]
    bus_frames = sum(n for i, n in ids.items() if i != ALERT_ID)
    assert bus_frames == sent
    frames = summary["frames"]
    assert summary["frames_received"] == bus_frames
    assert frames["accepted"] == sent and frames["lost"] == 0
    assert sum(frames["rejected"].values()) == 0
    rx = frames["receive"]
    assert rx["buffer_overflow"] == 0 and rx["counter_gap"] == 0
    # the kernel's own count: no frame dropped at the socket, no error frame
    assert rx["socket_overrun"] == 0 and rx["error_frames"] == 0 and rx["bus_errors"] == {}
    assert rx["lost_by_cause"] == {"buffer_overflow": 0, "socket_overrun": 0, "bus": 0,
                                   "counter_gap": 0}


def test_canplayer_replay_equals_monitor_input(node_run: dict[str, Any]) -> None:
    tmp: Path = node_run["tmp"]
    log: Path = node_run["node_log"]
    ref = _suspid("monitor", "--input", str(log), *_config(tmp, False), *MON_ARGS)
    assert ref.returncode == 0, ref.stderr
    ref_est = [json.loads(x) for x in ref.stdout.splitlines() if '"estimate"' in x]
    mon = _live_monitor(tmp, "replay.jsonl", alert_frames=False)
    play = subprocess.run(["canplayer", "-I", str(log), "vcan0=can0"], capture_output=True,
                          text=True, timeout=300)
    assert play.returncode == 0, play.stderr
    time.sleep(2.0)
    err = _stop(mon)
    assert mon.returncode == 0, err
    lines = _jsonl(tmp / "replay.jsonl")
    est = [d for d in lines if d["type"] == "estimate"]
    assert len(est) == len(ref_est) >= 8, lines[-1]
    for a, b in zip(est, ref_est):
        assert a["t"] == b["t"]
        for k, v in b["params"].items():
            assert a["params"][k] == pytest.approx(v, rel=1e-9, abs=1e-9), (a["t"], k)
    assert lines[-1]["frames"]["accepted"] == sum(1 for _ in log.open())


def _frames_of(log: Path) -> list[tuple[str, str]]:
    out = []
    for line in log.read_text().splitlines():
        parts = line.split()
        out.append((parts[0], parts[2]))
    return out


def test_injected_foreign_malformed_and_out_of_sequence_frames(node_run: dict[str, Any]) -> None:
    """canplayer plays the node's log with injected bad frames, cangen adds foreign traffic:
    each bad frame is counted under its reason, every valid frame is accepted."""
    tmp: Path = node_run["tmp"]
    frames = _frames_of(node_run["node_log"])[:4 * 500 * 8]     # 8 s of the node's stream
    n_valid = len(frames)
    bad: Counter[str] = Counter()
    lines = []
    for k, (ts, fr) in enumerate(frames):
        lines.append(f"{ts} can0 {fr}")
        ident, data = fr.split("#")
        if ident != "110" or k % 97:
            continue
        # after every 97th QC_Body frame: a repeat (out of sequence), a flipped payload bit
        # (CRC), a short payload (DLC) and a foreign ID
        lines.append(f"{ts} can0 {fr}")
        bad["counter_stale"] += 1
        flipped = f"{int(data[:2], 16) ^ 0x01:02X}{data[2:]}"
        lines.append(f"{ts} can0 {ident}#{flipped}")
        bad["crc"] += 1
        lines.append(f"{ts} can0 {ident}#{data[:8]}")
        bad["dlc"] += 1
        lines.append(f"{ts} can0 7AB#{data}")
        bad["unknown_id"] += 1
    log = tmp / "injected.log"
    log.write_text("\n".join(lines) + "\n")
    mon = _live_monitor(tmp, "injected.jsonl", "--window", "2", "--step", "1", alert_frames=False)
    n_gen = 300
    gen = subprocess.Popen(["cangen", "vcan0", "-I", "5A5", "-L", "8", "-g", "5", "-n", str(n_gen)])
    play = subprocess.run(["canplayer", "-I", str(log), "vcan0=can0"], capture_output=True,
                          text=True, timeout=300)
    assert play.returncode == 0, play.stderr
    assert gen.wait(timeout=120) == 0
    time.sleep(2.0)
    err = _stop(mon)
    assert mon.returncode == 0, err
    assert "Traceback" not in err
    summary = _jsonl(tmp / "injected.jsonl")[-1]
    f = summary["frames"]
    assert f["accepted"] == n_valid and f["lost"] == 0, summary
    want = {r: 0 for r in f["rejected"]}
    want.update(bad)
    want["unknown_id"] += n_gen
    got = dict(f["rejected"])
    # a repeat that reaches the monitor more than 7 sample periods after its original (a
    # starved guest) has a stale tick: rejected as no_sync instead of counter_stale
    got["counter_stale"] += got.pop("no_sync")
    want["counter_stale"] += want.pop("no_sync")
    assert got == want, f["rejected"]
    assert summary["frames_received"] == len(lines) + n_gen


def test_candump_recording_read_back(node_run: dict[str, Any]) -> None:
    """A ``candump -L`` recording (wall-clock arrival times) gives the node log's results:
    the data time is the sensor's tick in identify, diagnose and monitor."""
    rec: Path = node_run["candump"]
    log: Path = node_run["node_log"]
    fix = ["--fix", "m1=300", "--fix", "m2=40"]
    a = _suspid("identify", "--model", "quarter2", "--input", str(rec), *fix, "--json")
    b = _suspid("identify", "--model", "quarter2", "--input", str(log), *fix, "--json")
    assert a.returncode == 0 and b.returncode == 0, a.stderr + b.stderr
    ja, jb = json.loads(a.stdout), json.loads(b.stdout)
    assert ja["frames"]["time_base"] == "tick"
    # the recording also holds the monitor's SUSPID_Alert frames (valid frames of the DBC)
    assert ja["frames"]["accepted"] == jb["frames"]["accepted"] + _candump_ids(rec)[ALERT_ID]
    for k, v in jb["params"].items():
        assert ja["params"][k] == pytest.approx(v, rel=1e-9), k
    d = _suspid("diagnose", "--model", "quarter2", "--input", str(rec), *fix, "--json")
    assert d.returncode == 0, d.stderr
    assert json.loads(d.stdout)
    m = _suspid("monitor", "--input", str(rec), *_config(rec.parent, False), *MON_ARGS)
    r = _suspid("monitor", "--input", str(log), *_config(rec.parent, False), *MON_ARGS)
    assert m.returncode == 0 and r.returncode == 0, m.stderr + r.stderr
    em = [json.loads(x)["params"] for x in m.stdout.splitlines() if '"estimate"' in x]
    er = [json.loads(x)["params"] for x in r.stdout.splitlines() if '"estimate"' in x]
    assert len(em) == len(er) >= 8
    for x, y in zip(em, er):
        for k in y:
            assert x[k] == pytest.approx(y[k], rel=1e-9), k


def _write_log(path: Path, frames: list[Any]) -> int:
    """A candump ``-L`` log of ``frames`` (can.Message, data time), for canplayer."""
    path.write_text("".join(f"({m.timestamp:.6f}) can0 {m.arbitration_id:03X}#{bytes(m.data).hex().upper()}\n"
                            for m in frames))
    return len(frames)


def _settled(path: Path, quiet_s: float = 3.0, timeout: float = 180.0) -> None:
    """Wait until ``path`` has not grown for ``quiet_s`` (a recorder that fell behind, e.g.
    candump after a flood in a slow guest, has written out its socket queue: on SIGINT it
    exits without reading what is still queued)."""
    size, since = -1, time.monotonic()
    deadline = since + timeout
    while time.monotonic() < deadline:
        now = path.stat().st_size
        if now != size:
            size, since = now, time.monotonic()
        elif time.monotonic() - since >= quiet_s:
            return
        time.sleep(0.2)


def _stopped(pid: int) -> bool:
    """The process is stopped (state T in /proc/PID/stat)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] in ("T", "t")
    except (OSError, IndexError):
        return False


def _play(log: Path) -> None:
    play = subprocess.run(["canplayer", "-I", str(log), "vcan0=can0"], capture_output=True,
                          text=True, timeout=300)
    assert play.returncode == 0, play.stderr


def _cansend(frame: str) -> None:
    out = subprocess.run(["cansend", "vcan0", frame], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr


def test_lost_frames_counted_by_cause(tmp_path: Path) -> None:
    """The live monitor's ``frames.receive`` names every lost frame's cause, once.

    The node's stream goes through canplayer in segments: A (clean), B (every 50th QC_Body
    frame left out: counter gaps made at the source), then the monitor is stopped
    (SIGSTOP: a receiver that sleeps), cangen floods vcan0 until its kernel socket queue
    overflows and C (2 samples) is dropped with the flood; after SIGCONT, D, a controller
    error frame (RX overflow) with the next sample left out, E, and a bus-off error frame.
    candump (a large queue of its own) is the independent count.
    """
    # without the 10 Hz SN_Status: its loss rule goes by arrival time, and the replay's
    # pause (the flood) would read as 15 of them lost whenever it lasts 16 status periods
    frames = [m for m in SensorNode(NodeConfig(scenario="random", duration=5.0, rate=500)).frames()
              if m.arbitration_id != 0x310]
    starts = [i for i, m in enumerate(frames) if m.arbitration_id == 0x100]

    def samples(a: int, b: int) -> list[Any]:
        return frames[starts[a]:starts[b]]

    def plain(seg: list[Any]) -> bool:   # the 4 E2E frames of each sample
        return len(seg) == 4 * len({m.timestamp for m in seg}) and \
            all(m.arbitration_id in (0x100, 0x110, 0x111, 0x112) for m in seg)

    seg_a = samples(0, 500)
    seg_b, cut = [], []
    for k in range(500, 1001):
        for m in samples(k, k + 1):
            (cut if k % 50 == 25 and m.arbitration_id == 0x110 else seg_b).append(m)
    seg_c = samples(1001, 1003)
    seg_d = samples(1003, 1501)
    lost_bus = samples(1501, 1502)
    seg_e = samples(1502, 2000)
    assert plain(seg_c) and plain(lost_bus) and len(cut) == 10
    logs = {}
    for name, seg in (("a", seg_a), ("b", seg_b), ("c", seg_c), ("d", seg_d), ("e", seg_e)):
        logs[name] = tmp_path / f"{name}.log"
        _write_log(logs[name], seg)
    # -d: candump reports the frames its own socket dropped (a slow guest under the flood)
    dump = _start(["candump", "-L", "-d", "-r", str(64 << 20), "vcan0"],
                  tmp_path / "candump.log")
    mon = _live_monitor(tmp_path, "lost.jsonl", "--window", "2", "--step", "1",
                        alert_frames=False)
    flood = 50_000
    try:
        _play(logs["a"])
        _play(logs["b"])
        os.kill(mon.pid, signal.SIGSTOP)
        deadline = time.monotonic() + 60
        while not _stopped(mon.pid):
            assert time.monotonic() < deadline
            time.sleep(0.01)
        gen = subprocess.run(["cangen", "vcan0", "-I", "5A5", "-L", "8", "-g", "0", "-n",
                              str(flood)], capture_output=True, text=True, timeout=600)
        assert gen.returncode == 0, gen.stderr
        _play(logs["c"])
    finally:
        os.kill(mon.pid, signal.SIGCONT)
    time.sleep(3.0)    # the resumed monitor reads its full queue
    _play(logs["d"])
    _cansend("20000004#0001000000000000")      # controller problem: RX overflow
    _play(logs["e"])
    _cansend("20000040#0000000000000000")      # bus-off
    time.sleep(2.0)
    err = _stop(mon)
    _settled(tmp_path / "candump.log")
    _stop(dump)
    assert mon.returncode == 0, err
    assert "Traceback" not in err
    summary = _jsonl(tmp_path / "lost.jsonl")[-1]
    f = summary["frames"]
    r = f["receive"]
    dumped = (tmp_path / "candump.log").read_text().splitlines()
    seen = sum(1 for x in dumped if x.startswith("("))   # candump takes no error frames
    drops = max((int(x.rsplit("total drops ", 1)[1].rstrip(")"))
                 for x in dumped if x.startswith("DROPCOUNT")), default=0)
    node_sent = len(seg_a) + len(seg_b) + len(seg_c) + len(seg_d) + len(seg_e)
    # what reached the bus: candump's frames and its own socket's drops (the independent
    # count; in a slow guest candump too can fall behind the flood)
    assert seen + drops == node_sent + flood
    # the kernel's drop count is exactly what reached the bus but not the monitor
    assert r["socket_overrun"] > len(seg_c)
    assert r["read"] + r["socket_overrun"] == node_sent + flood + 2
    assert r["error_frames"] == 2 and summary["frames_received"] == r["read"] - 2
    assert r["bus_errors"] == {"bus_off": 1, "controller": 1, "rx_overflow": 1}
    assert f["rejected"]["frame_type"] == 0          # error frames never reach the decoder
    # node frames the kernel dropped: C, and any of D that came while the resumed monitor's
    # queue was still full of the flood
    node_lost = node_sent - f["accepted"]
    assert node_lost >= len(seg_c)
    assert f["rejected"]["unknown_id"] == flood - (r["socket_overrun"] - node_lost)
    assert sum(f["rejected"].values()) == f["rejected"]["unknown_id"]
    # counter gaps: the node frames lost in the socket, the sample after the RX overflow,
    # and the 10 left out at the source -- each once, under its cause
    assert r["counter_gap"] == node_lost + len(lost_bus) + len(cut), (r, f)
    assert r["counter_gap_after"] == {"socket_overrun": node_lost, "bus": len(lost_bus),
                                      "buffer_overflow": 0, "none": len(cut)}
    assert r["lost_by_cause"] == {"buffer_overflow": 0, "socket_overrun": r["socket_overrun"],
                                  "bus": len(lost_bus), "counter_gap": len(cut)}
    assert r["buffer_overflow"] == 0
