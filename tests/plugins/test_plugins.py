"""Effects and models from another installed package, through the entry points only.

``suspid-testplugin`` (``tests/plugins/suspid_testplugin``, its own ``pyproject.toml``) is
installed with pip into a temporary folder (``conftest.py``) and declares the strut effect
``rebound_stop`` (group ``suspid.effects``) and the model ``qcar5`` (group
``suspid.models``). Nothing of the project is edited: the commands see the plug-in through
``PYTHONPATH`` alone, and without it they do not know either name.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from suspid.errors import UsageError
from suspid.effects import PhysicalEffect
from suspid.effects.base import _check_plugin

from .conftest import env_with

#: seed Table 1 quarter car (SI), the truth of the quarter2 records
TABLE1 = dict(m1=275.0, k1=150000.0, c1=1120.0, m2=27.0, k2=310000.0, c2=3100.0)
#: qcar5 truth (its documented defaults)
Q5 = dict(m1=300.0, c1=1500.0, k1=20000.0, m2=40.0, k2=200000.0)
STOP = {"gap": 0.01, "k_top": 300000.0}


def suspid(site: Path | None, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "suspid", *args], capture_output=True, text=True,
                          timeout=600, env=env_with(site))


def _record(site: Path | None, tmp: Path, model: str, truth: dict[str, float], *extra: str) -> Path:
    csv = tmp / f"{model}.csv"
    curb = tmp / "curb.toml"
    curb.write_text("[simulate]\nheight_m = -0.06\n")
    r = suspid(site, "simulate", "--model", model, "--scenario", "curb", "--config", str(curb),
               "--duration", "1.6", "--fs", "200", *[f"--param={k}={v}" for k, v in truth.items()],
               "--noise", "0.005", "--out", str(csv), *extra)
    assert r.returncode == 0, r.stderr
    return csv


def _diagnose(site: Path | None, csv: Path, model: str, truth: dict[str, float]) -> dict[str, Any]:
    free = [k for k in truth if not k.startswith("m")]
    r = suspid(site, "diagnose", "--model", model, "--input", str(csv),
               *[f"--fix={k}={truth[k]}" for k in ("m1", "m2")],
               *[f"--init={k}={0.7 * truth[k]}" for k in free], "--maxfev", "1200", "--json")
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def _check_found(out: dict[str, Any], truth: dict[str, float]) -> None:
    ev = out["evidence"]
    assert out["effect"] is not None, ev["verdict"]
    assert out["effect"]["name"] == "rebound_stop", ev["verdict"]
    for k, v in STOP.items():
        assert math.isclose(out["effect"]["params"][k], v, rel_tol=0.25), (k, out["effect"]["params"])
    assert ev["candidates"]["rebound_stop"]["refit"]["accepted"] is True
    assert ev["effect_sites"] == ["strut"]
    b, a = out["baseline"], out["augmented"]
    assert a["cost"] < 0.2 * b["cost"]
    for c in b["rms_residual"]:
        assert a["rms_residual"][c] < b["rms_residual"][c], c
    # the linear fit bends the suspension to cover the stop; the augmented one is right
    err_b = max(abs(b["params"][k] / truth[k] - 1) for k in ("c1", "k1"))
    err_a = max(abs(a["params"][k] / truth[k] - 1) for k in ("c1", "k1"))
    assert err_b > 0.05 and err_a < 0.03, (err_b, err_a)


@pytest.mark.slow
def test_plugin_effect_is_injected_found_and_refitted(plugin_site: Path, tmp_path: Path) -> None:
    spec = f"rebound_stop:gap={STOP['gap']},k_top={STOP['k_top']}"
    csv = _record(plugin_site, tmp_path, "quarter2", TABLE1, "--effect", spec)
    _check_found(_diagnose(plugin_site, csv, "quarter2", TABLE1), TABLE1)
    # without the plug-in the project does not know the effect
    r = suspid(None, "simulate", "--model", "quarter2", "--effect", spec, "--out", str(tmp_path / "x.csv"))
    assert r.returncode == 2 and r.stderr.startswith("error: unknown effect 'rebound_stop'"), r.stderr
    out = _diagnose(None, csv, "quarter2", TABLE1)
    assert (out["effect"] or {}).get("name") != "rebound_stop"
    assert "rebound_stop" not in out["evidence"].get("candidates", {})


@pytest.mark.slow
def test_plugin_model_and_effect_through_diagnose(plugin_site: Path, tmp_path: Path) -> None:
    spec = f"rebound_stop:gap={STOP['gap']},k_top={STOP['k_top']}"
    csv = _record(plugin_site, tmp_path, "qcar5", Q5, "--effect", spec)
    out = _diagnose(plugin_site, csv, "qcar5", Q5)
    assert out["model"] == "qcar5" and set(out["baseline"]["params"]) == set(Q5)
    _check_found(out, Q5)
    r = suspid(None, "diagnose", "--model", "qcar5", "--input", str(csv))
    assert r.returncode == 2 and "invalid choice: 'qcar5'" in r.stderr


@pytest.mark.slow
def test_plugin_model_through_monitor(plugin_site: Path, tmp_path: Path) -> None:
    csv, log = tmp_path / "q5.csv", tmp_path / "q5.log"
    r = suspid(plugin_site, "simulate", "--model", "qcar5", "--scenario", "iso8608", "--duration", "12",
               "--fs", "200", "--noise", "0.005", "--out", str(csv))
    assert r.returncode == 0, r.stderr
    r = suspid(plugin_site, "encode", "--input", str(csv), "--out", str(log))
    assert r.returncode == 0, r.stderr
    # the DBC names no qcar5 channel: the plug-in's user maps its signals
    sig = {"x1": "QC_Body.Disp", "x1_dot": "QC_Body.Vel", "x2": "QC_Wheel.Disp",
           "x2_dot": "QC_Wheel.Vel", "r": "QC_Road.Disp", "r_dot": "QC_Road.Vel"}
    r = suspid(plugin_site, "monitor", "--model", "qcar5", "--input", str(log),
               *[f"--map={k}={v}" for k, v in sig.items()], "--fix=m1=300", "--fix=m2=40",
               "--nominal=c1=2500", "--jsonl")
    assert r.returncode == 0, r.stderr
    lines = [json.loads(x) for x in r.stdout.splitlines() if x.strip()]
    est = [x for x in lines if x["type"] == "estimate"]
    assert len(est) >= 4
    assert set(est[-1]["params"]) == set(Q5)
    for k in ("c1", "k1", "k2"):
        assert math.isclose(est[-1]["params"][k], Q5[k], rel_tol=0.03), (k, est[-1]["params"][k])
    # c1 = 1500 is 40 % below the nominal 2500: the monitor alerts on it
    alerts = [x for x in lines if x["type"] == "alert"]
    assert alerts and {a["parameter"] for a in alerts} == {"c1"}


def test_plugin_model_brings_its_own_doe_design(plugin_site: Path) -> None:
    r = suspid(plugin_site, "doe", "--model", "qcar5", "--ids", "1,14", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert (out["design"], out["model"], out["total"], out["successes"]) == ("L27-3", "qcar5", 2, 2)
    assert "J" not in out["setup"]["column_mapping"]
    assert out["setup"]["column_mapping"]["K"] == "k2 -> k2"
    r = suspid(None, "doe", "--model", "qcar5")
    assert r.returncode == 2 and "invalid choice: 'qcar5'" in r.stderr


def test_broken_plugin_is_a_one_line_error(broken_site: Path, tmp_path: Path) -> None:
    r = suspid(broken_site, "simulate", "--model", "quarter2", "--effect", "coulomb_friction:F=100",
               "--out", str(tmp_path / "x.csv"))
    assert r.returncode == 2
    err = r.stderr.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in r.stderr, r.stderr
    assert err[0].startswith("error: effect plugin 'ghost' (suspid_brokenplugin:Ghost, from "
                             "suspid-brokenplugin"), err[0]
    assert "cannot be loaded: AttributeError" in err[0]


class _NoHooks(PhysicalEffect):
    name = "no_hooks"

    def law(self, site: Any, base: Any) -> Any:
        return lambda s, sd: 0.0


def test_plugin_classes_are_checked() -> None:
    with pytest.raises(UsageError, match="does not implement regressors, from_coefficients"):
        _check_plugin("effect plugin 'no_hooks'", "no_hooks", _NoHooks)
    with pytest.raises(UsageError, match="class's name is 'no_hooks', expected 'other'"):
        _check_plugin("effect plugin 'other'", "other", _NoHooks)
    with pytest.raises(UsageError, match="expected a subclass"):
        _check_plugin("effect plugin 'x'", "x", dict)
