"""``suspid diagnose --road unknown``: a strut effect found in the body equations, no road.

The records are simulated with the effect in the struts (the nonlinear simulator) over an
ISO 8608 road, then reduced to body acceleration and ride height with 2 % noise.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from estimator.diagnose.roadfree import diagnose_road_unknown
from suspid.effects import effect_classes
from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement, write_measurement
from suspid.models import get_model
from suspid.models.base import SuspensionModel
from suspid.simulate import simulate
from tests.conftest import REPO, suspid_env
from tests.core.test_roadfree import drive, held, ride_heights


def effect_drive(name: str, effect: str, values: dict[str, Any], seed: int = 1
                 ) -> tuple[SuspensionModel, dict[str, float], Measurement]:
    model = get_model(name)
    p = model.defaults()
    model.extra_force = (effect_classes()[effect](**values).force_fn(model),)
    t, road, x0 = make_scenario(model, "iso8608", duration=10.0, fs=200.0, params=p, seed=seed,
                                v_kmh=50.0)
    ch = simulate(model, p, t, road, x0)
    model.extra_force = ()
    ch.update(ride_heights(model, p, ch))
    names = [f"{model.coords[j]}_ddot" for j in model.body_rows(p)] + list(model.ride_heights)
    rng = np.random.default_rng(seed + 1000)
    meas = {n: ch[n] + 0.02 * np.std(ch[n]) * rng.standard_normal(t.size) for n in names}
    return model, p, Measurement(t=t, measured=meas, source=f"{name} {effect}")


@pytest.mark.parametrize("name,effect,values,key,tol", [
    ("quarter2", "coulomb_friction", {"F": 100.0}, "F", 0.15),
    ("quarter2", "asymmetric_damping", {"c_rebound": 2000.0, "c_compression": 1000.0},
     "c_rebound", 0.05),
    ("quarter2", "progressive_spring", {"k_cubic": 2e6}, "k_cubic", 0.15),
    ("half4", "coulomb_friction", {"F": 120.0}, "F", 0.15),
])
@pytest.mark.slow
def test_strut_effect_found_without_road(name: str, effect: str, values: dict[str, Any],
                                         key: str, tol: float) -> None:
    """The effect in the struts is named, its parameter comes out near the truth, and the
    augmented fit's equation error is smaller than the baseline's."""
    model, p, meas = effect_drive(name, effect, values)
    r = diagnose_road_unknown(model, meas, held(model, p))
    assert r.effect is not None and r.effect.name == effect, r.evidence["verdict"]
    assert abs(r.effect.values[key] / values[key] - 1) < tol, r.effect.values
    assert r.augmented.cost < 0.95 * r.baseline.cost
    out = r.to_json()
    assert out["road"] == "unknown" and out["effect"]["name"] == effect
    assert "tire_liftoff" in out["evidence"]["not_tried"]


def test_linear_struts_have_no_effect() -> None:
    """A linear suspension: every candidate is tried and none is chosen."""
    model, p, meas = drive("quarter2", duration=10.0, fs=200.0)
    r = diagnose_road_unknown(model, meas, held(model, p))
    assert r.effect is None and "no missing effect" in r.evidence["verdict"]
    assert len(r.evidence["candidates"]) >= 5
    assert r.augmented is r.baseline


def test_accelerometers_alone_say_why_nothing_is_tried() -> None:
    model, p, meas = drive("quarter2", sensors="accelerometers", duration=10.0, fs=500.0)
    r = diagnose_road_unknown(model, meas, held(model, p))
    assert r.effect is None and "ride height" in r.evidence["verdict"]


@pytest.mark.slow
def test_cli_diagnose_road_unknown(tmp_path: Path) -> None:
    """The command on a CSV without a road column: the contract's object with road unknown."""
    model, p, meas = effect_drive("quarter2", "coulomb_friction", {"F": 100.0})
    cols = {"x1_ddot": meas.measured["x1_ddot"], "x1": np.cumsum(meas.measured["d"]) * 0,
            "d": meas.measured["d"]}
    cols.pop("x1")
    csv = tmp_path / "friction.csv"
    write_measurement(csv, meas.t, cols)
    proc = subprocess.run([sys.executable, "-m", "suspid", "diagnose", "--model", "quarter2",
                           "--input", str(csv), "--fix", "m1=300", "--fix", "m2=40", "--road",
                           "unknown", "--json"], capture_output=True, text=True, env=suspid_env(),
                          cwd=REPO, timeout=120)
    if proc.returncode == 2 and "no measured channel" in proc.stderr:
        pytest.fail("the CSV reader does not read the ride height d: " + proc.stderr)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["effect"]["name"] == "coulomb_friction" and out["road"] == "unknown"
    assert set(out) >= {"baseline", "augmented", "effect", "evidence"}
