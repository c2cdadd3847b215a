"""The README's main job, ``tools/demo.py``, run as a user runs it: every stage reports."""
from __future__ import annotations

import re
import subprocess
import sys

import pytest

from tests.conftest import REPO, suspid_env

#: the node paced at 8x on a live virtual bus, the monitor keeping up in wall-clock time
pytestmark = pytest.mark.realtime


def test_demo_reports_parameters_alert_on_the_bus_and_the_ekf_comparison(tmp_path) -> None:
    proc = subprocess.run([sys.executable, str(REPO / "tools" / "demo.py"), str(tmp_path)],
                          capture_output=True, text=True, env=suspid_env(), cwd=REPO,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = proc.stdout
    n = re.search(r"frames accepted (\d+), windows identified (\d+)", out)
    # 60 s of the production set (about 1,510 frames/s), none of them lost
    assert n is not None and int(n.group(1)) > 85_000 and int(n.group(2)) >= 30, out
    assert re.search(r"ALERT t = \d+\.\d s: c1 = ", out), out
    assert re.search(r"FORECAST t = \d+\.\d s: c1 = ", out), out
    # the monitor's alert and forecast frames reach the node even when the monitor fits
    # its windows seconds after the node at 8x has sent its last frame
    assert "the node received 1 alert and 1 forecast frame(s) on the bus" in out, out
    assert re.search(r"c1 RMSE \(% of truth\)\s+\d+\.\d+\s+\d+\.\d+", out), out
    assert (tmp_path / "compare-c1.png").stat().st_size > 10_000
    assert (tmp_path / "alerts.jsonl").read_text().strip()
