"""``suspid doe`` follows the contract: JSON on stdout, progress only on stderr."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from suspid.cli import main
from tests.conftest import write_config


def test_doe_json_contract_and_progress_on_stderr(capsys: pytest.CaptureFixture[str],
                                                  tmp_path: Path) -> None:
    rc = main(["doe", "--model", "quarter1", "--cost", "frobenius", "--ids", "1,16",
               "--config", write_config(tmp_path, "[doe]\nprogress = true\n"), "--json"])
    cap = capsys.readouterr()
    assert rc == 0
    out = json.loads(cap.out)  # stdout is exactly one JSON object
    assert out["design"] == "L16-4"
    assert out["total"] == 2 and out["successes"] == 2
    for e in out["experiments"]:
        assert {"id", "true", "identified", "max_rel_error", "success"} <= set(e)
        assert e["identified"]["m"] == e["true"]["m"]  # masses fixed by default
        assert e["start"]["c"] == pytest.approx(0.5 * e["true"]["c"])
    assert "2/2" in cap.err and "[" in cap.err
    assert out["setup"]["horizon_s"] > 0 and out["setup"]["sample_rate_hz"] > 0


def test_doe_half4_records_the_choices_the_seed_leaves_out(capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["doe", "--model", "half4", "--ids", "1", "--init-scale", "0.75", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0
    ch = out["setup"]["choices"]
    assert {"column_mapping", "m", "I", "horizon_s", "sample_rate_hz"} <= set(ch)
    assert out["setup"]["constants"]["a1"] == 0.48
    e = out["experiments"][0]
    assert e["start"]["k3"] == pytest.approx(0.75 * 1000.0)
    assert e["success"] is True


def test_doe_noisy_success_is_the_3_sigma_band(capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["doe", "--model", "quarter1", "--noise", "0.3", "--ids", "2,7", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0
    for e in out["experiments"]:
        inside = all(abs(e["identified"][k] - e["true"][k]) <= 3 * e["stderr"][k] for k in e["stderr"])
        assert e["success"] == inside
        assert all(v is not None and v > 0 for v in e["stderr"].values())


@pytest.mark.parametrize("argv,needle", [
    (["--init-scale", "0"], "--init-scale"),
    (["--noise", "-1"], "--noise"),
    (["--ids", "40"], "--ids"),
    (["--ids", "a,b"], "--ids"),
])
def test_doe_bad_usage_exits_2_with_one_error_line(argv: list[str], needle: str,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["doe", "--model", "quarter1", "--json"] + argv)
    cap = capsys.readouterr()
    assert rc == 2
    assert cap.out == ""
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and needle in lines[0]
