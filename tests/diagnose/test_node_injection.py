"""Undeclared effects injected in the sensor node are found by diagnose from the CAN log."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from firmware_sim.plant import Plant
from suspid.cli import main
from suspid.excitation import make_scenario
from suspid.models import get_model
from suspid.effects import inject

from ..conftest import TABLE1

EFFECTS = ["coulomb_friction:F=150", "sensor_delay:channels=x2,delay_s=0.01"]


def test_chunked_plant_with_effects_equals_whole_record_simulation() -> None:
    m = get_model("quarter2")
    t, road, x0 = make_scenario(m, "bump", duration=2.5, fs=400, params=TABLE1)
    plant = Plant(m, TABLE1, t, road, x0, chunk_s=0.5, effects=EFFECTS)
    rows = [plant.sample(k) for k in range(t.size)]
    ref = inject(m, EFFECTS).simulate(TABLE1, t, road, x0)
    linear = Plant(m, TABLE1, t, road, x0, chunk_s=0.5)
    lin_rows = [linear.sample(k) for k in range(t.size)]
    for c in ("x1", "x2", "x1_dot", "x2_dot"):
        got = np.array([r[c] for r in rows])
        assert np.max(np.abs(got - ref[c])) <= 1e-9 * np.max(np.abs(ref[c]))
        lin = np.array([r[c] for r in lin_rows])
        assert np.max(np.abs(got - lin)) > 0.01 * np.max(np.abs(lin))  # the effect is there


@pytest.mark.slow
def test_node_friction_found_by_diagnose_from_log(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    log = tmp_path / "node.log"
    params = [a for k, v in TABLE1.items() for a in ("--param", f"{k}={v}")]
    rc = main(["node", "--scenario", "bump", "--model", "quarter2", "--interface", "virtual",
               "--channel", "inj-test", "--speed", "0", "--duration", "2", "--rate", "250",
               "--log", str(log), "--effect", "coulomb_friction:F=150", *params])
    assert rc == 0
    capsys.readouterr()
    rc = main(["diagnose", "--model", "quarter2", "--input", str(log), "--fix", "m1=275",
               "--fix", "m2=27", "--init", "c1=800", "--init", "k1=100000", "--init", "c2=2000",
               "--init", "k2=200000", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["effect"]["name"] == "coulomb_friction"
    assert out["effect"]["params"]["F"] == pytest.approx(150, rel=0.25)
    assert out["augmented"]["params"]["c1"] == pytest.approx(1120, rel=0.05)


def test_node_rejects_unknown_effect(capsys: pytest.CaptureFixture) -> None:
    rc = main(["node", "--scenario", "bump", "--interface", "virtual", "--channel", "x",
               "--speed", "0", "--duration", "1", "--effect", "warp_drive:F=1"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "warp_drive" in err[0]


def test_node_rejects_a_sensor_delay_longer_than_the_run(capsys: pytest.CaptureFixture) -> None:
    rc = main(["node", "--scenario", "bump", "--interface", "virtual", "--channel", "x",
               "--speed", "0", "--duration", "1", "--effect", "sensor_delay:channels=x1,delay_s=10"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: effect sensor_delay: delay_s 10 s"), err
