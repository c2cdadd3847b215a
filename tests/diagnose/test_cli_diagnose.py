"""`suspid simulate --effect` + `suspid diagnose --json`: friction on the quarter car found through the CLI."""
from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from suspid.cli import diagnose, fleet, identify, main
from suspid.models import get_model
from tests.conftest import write_config

from ..conftest import TABLE1


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "suspid", *args], capture_output=True, text=True,
                          timeout=300)


@pytest.mark.slow
def test_must_show_coulomb_friction_on_2dof(tmp_path: Path) -> None:
    csv = tmp_path / "friction.csv"
    truth = [f"--param={k}={v}" for k, v in TABLE1.items()]
    r = run("simulate", "--model", "quarter2", "--scenario", "bump", "--duration", "1.6", "--fs", "200",
            *truth, "--effect", "coulomb_friction:F=120", "--noise", "0.005", "--out", str(csv))
    assert r.returncode == 0, r.stderr
    rough = [f"--init={k}={0.7 * TABLE1[k]}" for k in ("c1", "k1", "c2", "k2")]
    png = tmp_path / "evidence.png"
    r = run("diagnose", "--model", "quarter2", "--input", str(csv), "--fix", f"m1={TABLE1['m1']}",
            "--fix", f"m2={TABLE1['m2']}", *rough, "--maxfev", "1200", "--json", "--plot", str(png))
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    for key in ("baseline", "augmented", "effect", "evidence"):
        assert key in out
    for blk in ("baseline", "augmented"):
        assert set(out[blk]) >= {"params", "rms_residual", "cost"}
        assert set(out[blk]["params"]) == set(TABLE1)
    assert out["effect"]["name"] == "coulomb_friction"
    assert math.isclose(out["effect"]["params"]["F"], 120, rel_tol=0.25)
    for c, v in out["augmented"]["rms_residual"].items():
        assert v < out["baseline"]["rms_residual"][c], c
    for k in ("c1", "k1"):
        assert math.isclose(out["augmented"]["params"][k], TABLE1[k], rel_tol=0.05), k
    assert png.stat().st_size > 10_000


def test_bad_effect_option_is_one_line_error(tmp_path: Path) -> None:
    r = run("simulate", "--model", "quarter2", "--effect", "bump_stop:gap=0.01", "--out", str(tmp_path / "x.csv"))
    assert r.returncode == 2
    assert r.stderr.startswith("error:") and "k_stop" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.slow
def test_works_on_a_can_log(tmp_path: Path) -> None:
    csv, log = tmp_path / "bs.csv", tmp_path / "bs.log"
    truth = [f"--param={k}={v}" for k, v in TABLE1.items()]
    r = run("simulate", "--model", "quarter2", "--scenario", "bump", "--duration", "1.6", "--fs", "200",
            *truth, "--effect", "bump_stop:gap=0.01,k_stop=300000", "--out", str(csv))
    assert r.returncode == 0, r.stderr
    r = run("encode", "--input", str(csv), "--out", str(log))
    assert r.returncode == 0, r.stderr
    rough = [f"--init={k}={0.7 * TABLE1[k]}" for k in ("c1", "k1", "c2", "k2")]
    r = run("diagnose", "--model", "quarter2", "--input", str(log), "--fix", f"m1={TABLE1['m1']}",
            "--fix", f"m2={TABLE1['m2']}", *rough, "--maxfev", "1200", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["effect"]["name"] == "bump_stop"
    assert math.isclose(out["effect"]["params"]["gap"], 0.01, rel_tol=0.25)
    assert math.isclose(out["effect"]["params"]["k_stop"], 3e5, rel_tol=0.25)
    assert out["frames"]["accepted"] > 0


@pytest.mark.slow
def test_half4_through_the_cli(tmp_path: Path, capsys) -> None:
    csv, png = tmp_path / "h4.csv", tmp_path / "h4.png"
    rc = main(["simulate", "--model", "half4", "--scenario", "bump", "--duration", "1.6", "--fs", "200",
               "--effect", "bump_stop:gap=0.02,k_stop=200000", "--noise", "0.005", "--out", str(csv)])
    assert rc == 0
    capsys.readouterr()
    fixed = [a for k, v in (("m", 1200), ("I", 1500), ("m1", 40), ("m2", 40), ("a1", 1.2), ("a2", 1.4))
             for a in ("--fix", f"{k}={v}")]
    rough = [a for k, v in (("c1", 2000), ("c2", 2000), ("k1", 30000), ("k2", 30000), ("k3", 2e5), ("k4", 2e5))
             for a in ("--init", f"{k}={0.7 * v}")]
    rc = main(["diagnose", "--model", "half4", "--input", str(csv), *fixed, *rough, "--maxfev", "1200",
               "--json", "--plot", str(png)])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["effect"]["name"] == "bump_stop"
    assert math.isclose(out["effect"]["params"]["gap"], 0.02, rel_tol=0.25)
    assert out["evidence"]["effect_sites"] == ["front strut", "rear strut"]
    assert "asymmetric_damping (both struts)" in out["evidence"]["limits"]
    for k in ("c1", "c2", "k1", "k2"):
        assert math.isclose(out["augmented"]["params"][k], 2000 if k[0] == "c" else 30000, rel_tol=0.05), k
    assert png.stat().st_size > 10_000


def test_quarter1_text_output_and_option_errors(tmp_path: Path, capsys) -> None:
    csv = tmp_path / "q1.csv"
    rc = main(["simulate", "--model", "quarter1", "--scenario", "curb", "--duration", "1.6", "--fs", "200",
               "--config", write_config(tmp_path, "[simulate]\nheight_m = 0.05\n", "curb.toml"),
               "--effect", "sensor_offset:channel=x_dot,offset=0.01", "--noise", "0.005",
               "--out", str(csv)])
    assert rc == 0
    capsys.readouterr()
    args = ["diagnose", "--model", "quarter1", "--input", str(csv), "--fix", "m=300", "--init", "c=1050",
            "--init", "k=14000"]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert text.startswith("model quarter1: effect sensor_offset") and "offset=0.0" in text
    bad = write_config(tmp_path, "[fit]\nmultistart = -1\n")
    assert main([*args, "--config", bad]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {bad}: fit.multistart: ")


@pytest.mark.slow
def test_full7_through_the_cli(tmp_path: Path, capsys) -> None:
    csv, png = tmp_path / "f7.csv", tmp_path / "f7.png"
    rc = main(["simulate", "--model", "full7", "--scenario", "iso8608", "--speed", "50", "--duration", "1.6",
               "--fs", "200", "--effect", "progressive_spring:k_cubic=5e6", "--noise", "0.005",
               "--out", str(csv)])
    assert rc == 0
    capsys.readouterr()
    truth = get_model("full7").defaults()
    free = [k for k in truth if k not in get_model("full7").known]
    rc = main(["diagnose", "--model", "full7", "--input", str(csv),
               *[f"--fix={k}={truth[k]}" for k in get_model("full7").known],
               *[f"--init={k}={0.7 * truth[k]}" for k in free], "--maxfev", "2000", "--json",
               "--plot", str(png)])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["model"] == "full7"
    assert out["effect"]["name"] == "progressive_spring"
    assert math.isclose(out["effect"]["params"]["k_cubic"], 5e6, rel_tol=0.25)
    assert out["evidence"]["effect_sites"] == ["front-left strut", "front-right strut", "rear-left strut",
                                               "rear-right strut"]
    for k in free:
        assert math.isclose(out["augmented"]["params"][k], truth[k], rel_tol=0.05), k
    assert png.stat().st_size > 10_000


def test_the_fitting_commands_share_the_identifier_s_options(tmp_path: Path, capsys) -> None:
    """diagnose and fleet take identify's fit options with the same names, types and
    defaults (one definition in suspid.cli._args); negative counts in the ``[fit]`` table of
    ``--config`` are refused in one line naming the file and the key."""
    def options(mod) -> dict:
        p = argparse.ArgumentParser()
        mod.add_parser(p.add_subparsers())
        sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))
        cmd = next(iter(sub.choices.values()))
        return {a.dest: (a.option_strings, a.default, a.type, a.metavar, a.choices)
                for a in cmd._actions if a.dest in ("cost", "maxfev")}

    ref = options(identify)
    assert len(ref) == 2 and ref["cost"][4] == ["sse", "frobenius"]
    assert options(diagnose) == ref and options(fleet) == ref
    csv = tmp_path / "q1.csv"
    assert main(["simulate", "--model", "quarter1", "--duration", "1", "--fs", "100", "--out", str(csv)]) == 0
    capsys.readouterr()
    for command, key, value in (("diagnose", "restarts", -1), ("fleet", "restarts", -2),
                                ("fleet", "multistart", -1)):
        bad = write_config(tmp_path, f"[fit]\n{key} = {value}\n", f"{command}-{key}.toml")
        assert main([command, "--model", "quarter1", "--input", str(csv), "--config", bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"error: {bad}: fit.{key}: expected an integer >= 0, got {value} "
                       "(integer)"], err


def test_effect_the_record_never_engages_is_warned(tmp_path: Path, capsys) -> None:
    """A bump stop 30 m away (a value in mm given as m) changes nothing: the output says so."""
    csv = tmp_path / "far.csv"
    rc = main(["simulate", "--model", "quarter2", "--scenario", "bump", "--duration", "1", "--fs", "200",
               "--effect", "bump_stop:gap=30,k_stop=1e5", "--out", str(csv), "--json"])
    assert rc == 0
    cap = capsys.readouterr()
    out = json.loads(cap.out)
    assert len(out["warnings"]) == 1 and "bump_stop:gap=30,k_stop=1e5" in out["warnings"][0]
    assert "never engages" in cap.err and "unit" in cap.err
    # the same stop within the record's deflection is not warned about
    rc = main(["simulate", "--model", "quarter2", "--scenario", "bump", "--duration", "1", "--fs", "200",
               "--effect", "bump_stop:gap=0.02,k_stop=1e5", "--out", str(csv), "--json"])
    assert rc == 0
    cap = capsys.readouterr()
    assert json.loads(cap.out)["warnings"] == [] and "warning" not in cap.err


def test_sensor_delay_longer_than_the_record_is_an_error(tmp_path: Path, capsys) -> None:
    rc = main(["simulate", "--model", "quarter2", "--scenario", "bump", "--duration", "2", "--fs", "200",
               "--effect", "sensor_delay:channels=x1,delay_s=8", "--out", str(tmp_path / "d.csv")])
    assert rc == 2
    err = capsys.readouterr().err
    assert err.startswith("error: effect sensor_delay: delay_s 8 s") and "(2 s)" in err
    assert err.count("\n") == 1 and not (tmp_path / "d.csv").exists()
