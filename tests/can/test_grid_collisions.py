"""Two frames of one message on one grid cell: the later is kept, and monitor and identify
say how many samples of which message fell on an already filled cell (a warning line, and
``collisions`` in the frame statistics), each sample counted once across overlapping windows."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from estimator.decode.log_input import load_log_as_measurement
from suspid.can.logs import open_log_writer
from suspid.cli import main
from suspid.io.csvio import read_measurement
from suspid.models import get_model
from tests.can.test_bus_channels import HEIGHT_DBC, MAP, STEP, T0, _frame

#: samples 50, 150, ... are sent twice, the second frame 0.6 ms (0.3 of the 2 ms step) later
#: with x1 raised by 1 mm: 10 in the 2 s record
EVERY, LATER, EXTRA, BUMP = 100, 6e-4, 10, 1e-3
WARNING = f"Height: {EXTRA} samples fell on a grid cell already filled; the later of each pair was kept"


@pytest.fixture(scope="module")
def doubled(q2_csv, tmp_path_factory) -> tuple[Path, Path]:
    """A candump log of ``q2_csv`` with the doubled frames, and its DBC."""
    d = tmp_path_factory.mktemp("collide")
    dbc = d / "height.dbc"
    dbc.write_text(HEIGHT_DBC)
    meas = read_measurement(q2_csv, get_model("quarter2"))
    x1, x2, r = meas.measured["x1"], meas.measured["x2"], meas.road["r"]
    log = d / "doubled.log"
    with open_log_writer(log) as w:
        for i, t in enumerate(meas.t):
            w.on_message_received(_frame(x1[i], x2[i], r[i], T0 + t, "can0"))
            if i % EVERY == EVERY // 2:
                w.on_message_received(_frame(x1[i] + BUMP, x2[i], r[i], T0 + t + LATER, "can0"))
    return log, dbc


def test_identify_keeps_the_later_and_says_so(doubled, q2_csv) -> None:
    log, dbc = doubled
    meas, frames = load_log_as_measurement(log, "quarter2", dbc, MAP)
    assert frames["collisions"] == {"Height": EXTRA}
    assert sum(WARNING in w for w in meas.warnings) == 1
    csv = read_measurement(q2_csv, get_model("quarter2")).measured["x1"]
    kept = np.flatnonzero(np.abs(meas.measured["x1"] - csv - BUMP) <= STEP)
    assert kept.size == EXTRA and np.all(kept % EVERY == EVERY // 2)


@pytest.mark.parametrize("jsonl", [True, False])
def test_monitor_summary_names_the_collisions(doubled, capsys, jsonl: bool) -> None:
    log, dbc = doubled
    args = ["monitor", "--model", "quarter2", "--input", str(log), "--dbc", str(dbc),
            "--map", MAP[0], "--map", MAP[1], "--map", MAP[2], "--fix", "m1=300",
            "--fix", "m2=40", "--window", "1", "--step", "0.5"]
    assert main(args + (["--jsonl"] if jsonl else [])) == 0
    out = capsys.readouterr().out
    if jsonl:
        summary = [json.loads(ln) for ln in out.splitlines()][-1]
        assert summary["windows_cut"] == 3                 # overlapping: 0-1, 0.5-1.5, 1-2 s
        assert summary["frames"]["collisions"] == {"Height": EXTRA}
        assert summary["warnings"] == [f"{log}: {WARNING}"]
    else:
        assert out.count(WARNING) == 1 and f"  warning: {log}: {WARNING}" in out.splitlines()
