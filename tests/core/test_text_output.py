"""Text output for people: few digits with units, ISO dates for epoch times, a readable
summary; the JSON keeps full precision."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from suspid.cli._format import data_time, num, summary_lines
from suspid.cli.monitor import _text
from suspid.models import get_model

from ..conftest import REPO, suspid_env


def test_numbers_and_times() -> None:
    assert num(2.4980000000000047, 3, "s") == "2.5 s"
    assert num(0.64394123, 3, "s") == "0.644 s"
    assert num(116.00845312, 4) == "116"
    assert num(float("nan")) == "-" and num(None) == "-" and num(3) == "3"
    assert data_time(12.345) == "t=12.35 s"
    # an epoch time (s since 1970) is a UTC date, not 1627275059.98s
    assert data_time(1627275059.9822) == "2021-07-26T04:50:59.98Z"


def test_monitor_summary_is_readable_lines() -> None:
    d = {"type": "summary", "baseline": "output_only", "data_s": 569.9967501163483,
         "wall_s": 0.64394123, "cpu_s": 1.7808498520000011, "realtime_factor": 885.2,
         "windows": 18, "skipped": 0, "missing_samples": 530,
         "frames": {"accepted": 60750, "rejected": {"malformed": 0, "unknown_id": 8467},
                    "ignored": 4568, "lost": 0, "time_base": "timestamp",
                    "arrival_slots": {"gnss_imu": {"period": 0.00999999}}},
         "windows_cut": 18, "warnings": ["w1"]}
    lines = _text(d).splitlines()
    assert lines[0] == ("summary: 18 windows fitted, 0 skipped, 18 cut, estimator output_only; "
                        "570 s of data in 0.644 s (885x real time), CPU 1.78 s")
    assert lines[1] == ("  frames: 60750 accepted, 8467 rejected (unknown_id 8467), 4568 ignored, "
                        "0 lost; time base timestamp")
    assert lines[2] == "  missing samples 530" and lines[3] == "  warning: w1"
    assert not any("{" in line or "'" in line for line in lines)
    assert summary_lines({"type": "summary", "alert_delay_s": 2.4980000000000047})[1] == \
        "  alert delay s 2.498"


def test_estimate_line_has_units_and_iso_time() -> None:
    d = {"type": "estimate", "t": 1627275059.9822, "params": {"m1": 300.0, "c1": 1500.41234},
         "stderr": {"c1": 7.5123}}
    assert _text(d, get_model("quarter2")) == "2021-07-26T04:50:59.98Z c1 1500.4 ± 7.5 N s/m"
    oo = {"type": "estimate", "t": 3.0, "params": {}, "stderr": {"f_body": None},
          "f_hz": 1.40529882, "zeta": 0.2756504}
    assert _text(oo) == "t=3.00 s f_body 1.41 Hz, zeta_body 0.276 (no standard error)"


def test_identify_text_has_digits_and_units_json_full_precision(tmp_path: Path) -> None:
    csv = tmp_path / "b.csv"
    run = [sys.executable, "-m", "suspid"]
    assert subprocess.run(run + ["simulate", "--model", "quarter1", "--scenario", "initial",
                                 "--duration", "2", "--fs", "200", "--noise", "0.01",
                                 "--out", str(csv)], env=suspid_env(), cwd=REPO,
                          capture_output=True).returncode == 0
    args = ["identify", "--model", "quarter1", "--input", str(csv), "--fix", "m=300",
            "--road", "zero"]
    txt = subprocess.run(run + args, env=suspid_env(), cwd=REPO, capture_output=True,
                         text=True, timeout=120).stdout
    js = json.loads(subprocess.run(run + args + ["--json"], env=suspid_env(), cwd=REPO,
                                   capture_output=True, text=True, timeout=120).stdout)
    (line,) = [x for x in txt.splitlines() if x.strip().startswith("c =")]
    value, rest = line.split("=", 1)[1].split(" ± ")
    assert float(value) == float(f"{js['params']['c']:.6g}")
    assert rest.split()[1:3] == ["N", "s/m"] and len(rest.split()[0].replace(".", "")) <= 4
    assert len(repr(js["params"]["c"])) > 8   # the JSON keeps every digit
