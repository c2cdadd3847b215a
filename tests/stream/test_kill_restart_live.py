"""A monitor killed mid-stream and restarted carries on: no alert lost, none duplicated.

Live, two processes as in the field: the sensor node paced in real time (x2) on an SLCAN
pseudo-terminal, ``suspid monitor`` attached with a durable alert file. The monitor is
SIGKILLed before the damper has worn through the alert limit; a new monitor attaches to the
same adapter with the same alert file, carries on with the live stream and raises the alert
exactly once -- on stdout and in the file. At x2 the new monitor has about 5 s of wall time
to start and attach before the data it needs for that alert go by (at x4, on a loaded
machine, it sometimes came too late).
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.conftest import REPO, start_slcan_node, suspid_env, write_config

#: the node paced at x2; the restarted monitor must attach before the alert's data go by
pytestmark = pytest.mark.realtime

FIX = ["--fix", "m1=300", "--fix", "m2=40", "--fix", "c2=300", "--fix", "k2=200000",
       "--nominal", "c1=1500", "--nominal", "k1=20000"]


def test_killed_live_monitor_restarts_and_raises_the_later_alert_once(tmp_path: Path) -> None:
    env = suspid_env()
    afile = tmp_path / "alerts.jsonl"
    # c1: 1500 N s/m until 5 s, then linearly to 750 at 40 s: crosses 70 % (1050) at 26 s
    node, path = start_slcan_node("--scenario", "damper-wear", "--duration", "40", "--speed", "2",
                                  "--wear-start", "5", "--wear-to", "0.5", "--config",
                                  write_config(tmp_path, "[node]\nopen_timeout_s = 30\n"
                                                         "linger_s = 1\n", "node.toml"))
    try:
        mon_cmd = [sys.executable, "-u", "-m", "suspid", "monitor", "--model", "quarter2",
                   "--interface", "slcan", "--channel", path, *FIX, "--alert-file", str(afile),
                   "--config", write_config(tmp_path, "[live]\nidle_timeout_s = 20\n"),
                   "--no-inspection", "--jsonl"]
        first_mon = subprocess.Popen(mon_cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env=env, cwd=REPO)
        seen = []
        assert first_mon.stdout is not None
        for line in first_mon.stdout:
            d = json.loads(line)
            seen.append(d)
            if d["type"] == "estimate" and d["t"] >= 9.0:
                os.kill(first_mon.pid, signal.SIGKILL)      # mid-stream, no cleanup
                break
        first_mon.wait(timeout=30)
        assert first_mon.returncode == -signal.SIGKILL
        assert not [d for d in seen if d["type"] == "alert"]
        killed_at = max(d["t"] for d in seen if d["type"] == "estimate")
        assert killed_at < 20.0                             # well before the crossing
        # no alert on disk yet (a forecast of the coming crossing may be)
        assert not afile.exists() or all(json.loads(l)["type"].startswith("forecast")
                                         for l in afile.read_text().splitlines() if l.strip())
        time.sleep(0.2)
        second = subprocess.run(mon_cmd, capture_output=True, text=True, env=env, cwd=REPO,
                                timeout=180)
        node.communicate(timeout=60)
    finally:
        if node.poll() is None:
            node.kill()
    assert second.returncode == 0, second.stderr
    out = [json.loads(l) for l in second.stdout.splitlines() if l.strip()]
    est = [d for d in out if d["type"] == "estimate"]
    alerts = [d for d in out if d["type"] == "alert"]
    assert est and est[0]["t"] > killed_at               # it carried on with the live stream
    assert [a["parameter"] for a in alerts] == ["c1"]     # the later alert: raised, once
    assert 26.0 < alerts[0]["t"] < 34.0
    on_disk = [json.loads(l) for l in afile.read_text().splitlines() if l.strip()]
    on_disk = [a for a in on_disk if a["type"] == "alert"]
    assert [(a["type"], a["parameter"]) for a in on_disk] == [("alert", "c1")]
    assert on_disk[0]["t"] == alerts[0]["t"]
