"""Data time from the sensor's clock: arrival jitter, bursts and delivery delay of the frame
timestamps change nothing in identify, diagnose and monitor (the SN_Sync tick and the
per-message counters place every frame in its sample)."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from estimator.decode import load_log_as_measurement
from suspid.cli import main

LINE = re.compile(r"^\((\d+\.\d+)\) (\S+) (\S+)(.*)$")
PERIOD = 0.002


def _perturbed(src: Path, dst: Path, kind: str, seed: int = 1) -> None:
    """``src`` with its timestamps as a USB adapter or a busy bus would deliver them; the
    frames themselves intact. Jitter reorders frames whose times come closer than it (the
    log is in arrival order); a delay goes through a FIFO (a bus and an adapter deliver in
    the order sent)."""
    rows = [LINE.match(line).groups() for line in src.read_text().splitlines()]  # type: ignore[union-attr]
    t = np.array([float(r[0]) for r in rows])
    rng = np.random.default_rng(seed)
    if kind == "jitter":              # 0.3 ms Gaussian arrival jitter
        t = t + rng.normal(0.0, 3e-4, t.size)
    elif kind == "burst":             # 5 sample periods delivered together
        t = (np.floor(t / (5 * PERIOD) + 1e-9) + 1) * 5 * PERIOD
    elif kind == "delay":             # exponential delivery delay, 2 ms mean, through a FIFO
        t = np.maximum.accumulate(t + rng.exponential(2e-3, t.size))
    order = np.argsort(t, kind="stable")
    dst.write_text("".join(f"({t[i] + 100.0:.6f}) {rows[i][1]} {rows[i][2]}{rows[i][3]}\n" for i in order))


@pytest.fixture(scope="module")
def node_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """8 s of a damper-wear node stream (all channels, noise on)."""
    p = tmp_path_factory.mktemp("tb") / "node.log"
    assert main(["node", "--scenario", "damper-wear", "--duration", "8", "--wear-start", "2",
                 "--speed", "0", "--log", str(p)]) == 0
    return p


FIX = ["--fix", "m1=300", "--fix", "m2=40"]


def _json(args: list[str], capsys: pytest.CaptureFixture[str]) -> object:
    capsys.readouterr()
    assert main(args) == 0
    return json.loads(capsys.readouterr().out)


def _estimates(args: list[str], capsys: pytest.CaptureFixture[str]) -> list[dict[str, object]]:
    capsys.readouterr()
    assert main(args) == 0
    return [json.loads(x) for x in capsys.readouterr().out.splitlines()
            if x.strip() and json.loads(x)["type"] in ("estimate", "summary")]


@pytest.mark.parametrize("kind", ["jitter", "burst", "delay"])
def test_arrival_times_do_not_move_the_data(node_log: Path, tmp_path: Path, kind: str,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / f"{kind}.log"
    _perturbed(node_log, bad, kind)
    clean, cs = load_log_as_measurement(node_log, "quarter2")
    got, gs = load_log_as_measurement(bad, "quarter2")
    # jitter may put a data frame of the very first sample before the first SN_Sync: it
    # has no tick yet (no_sync); every later frame is placed in its sample
    first = 4 if kind == "jitter" else 0
    rel = 1e-9
    assert gs["time_base"] == "tick"
    assert cs["accepted"] - first <= gs["accepted"] <= cs["accepted"]
    assert gs["rejected"]["no_sync"] == cs["accepted"] - gs["accepted"]   # type: ignore[index]
    np.testing.assert_array_equal(got.t, clean.t)
    for ch, v in clean.measured.items():
        np.testing.assert_array_equal(got.measured[ch][1:], v[1:])
    # identify
    a = _json(["identify", "--model", "quarter2", "--input", str(node_log), *FIX, "--json"], capsys)
    b = _json(["identify", "--model", "quarter2", "--input", str(bad), *FIX, "--json"], capsys)
    assert b["frames"]["time_base"] == "tick"   # type: ignore[index]
    for k, v in a["params"].items():            # type: ignore[index]
        assert b["params"][k] == pytest.approx(v, rel=rel), k   # type: ignore[index]
    # monitor
    mon = ["monitor", "--model", "quarter2", *FIX, "--fix", "c2=300", "--fix", "k2=200000",
           "--window", "2", "--step", "1", "--jsonl", "--no-inspection"]
    ea = _estimates([*mon, "--input", str(node_log)], capsys)
    eb = _estimates([*mon, "--input", str(bad)], capsys)
    assert eb[-1]["frames"]["time_base"] == "tick"   # type: ignore[index]
    assert len(ea) == len(eb) >= 6
    for x, y in zip(ea[:-1], eb[:-1]):
        assert x["t"] == y["t"]
        for k, v in x["params"].items():            # type: ignore[union-attr]
            assert y["params"][k] == pytest.approx(v, rel=rel), k   # type: ignore[index]


@pytest.mark.slow
def test_diagnose_on_a_burst_log(node_log: Path, tmp_path: Path,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    """Bursts of 5 sample periods once made identify/diagnose fail ("a timestamp outlier?")."""
    bad = tmp_path / "burst.log"
    _perturbed(node_log, bad, "burst")
    a = _json(["diagnose", "--model", "quarter2", "--input", str(node_log), *FIX, "--json"], capsys)
    b = _json(["diagnose", "--model", "quarter2", "--input", str(bad), *FIX, "--json"], capsys)
    pa, pb = a.get("params", a), b.get("params", b)   # type: ignore[union-attr]
    assert pa == pytest.approx(pb, rel=1e-9) if isinstance(pa, dict) and all(
        isinstance(v, float) for v in pa.values()) else json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)
