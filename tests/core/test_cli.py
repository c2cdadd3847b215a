"""The command line keeps the contract: JSON fields, one-line errors, exit status 2."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from estimator.doe.design import experiments
from suspid.cli import main
from suspid.cli._common import implausible_values
from suspid.models import MODELS, get_model

from ..conftest import TABLE1
from tests.conftest import write_config


def run(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "suspid", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=300)


@pytest.fixture(scope="module")
def bump_csv(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cli") / "bump.csv"
    params = [f"--param={k}={v}" for k, v in TABLE1.items()]
    r = run("simulate", "--model", "quarter2", "--scenario", "bump", "--duration", "3", *params,
            "--out", str(out))
    assert r.returncode == 0, r.stderr
    return out


def test_identify_json_contract(bump_csv: Path) -> None:
    r = run("identify", "--model", "quarter2", "--input", str(bump_csv), "--fix", "m1=275",
            "--fix", "m2=27", "--init", "c1=560", "--init", "k1=75000", "--init", "c2=1550",
            "--init", "k2=155000", "--cost", "sse", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    for key in ("model", "params", "fixed", "cost", "nfev", "success", "rms_residual", "stderr",
                "identifiable", "warnings"):
        assert key in out
    assert set(out["params"]) == set(TABLE1)
    assert sorted(out["fixed"]) == ["m1", "m2"]
    assert set(out["stderr"]) == {"c1", "k1", "c2", "k2"}
    for k in ("c1", "k1", "c2", "k2"):
        assert abs(out["params"][k] / TABLE1[k] - 1) < 1e-3
    assert out["success"] is True and out["identifiable"] is True


def test_identify_quarter1_free_mass_warns(tmp_path: Path) -> None:
    """Truth away from the defaults (which are the free start), so the fit has to move."""
    csv = tmp_path / "q1.csv"
    assert run("simulate", "--model", "quarter1", "--scenario", "initial", "--duration", "3",
               "--param", "m=450", "--param", "c=2500", "--param", "k=40000",
               "--out", str(csv)).returncode == 0
    r = run("identify", "--model", "quarter1", "--input", str(csv), "--json")
    out = json.loads(r.stdout)
    assert r.returncode == 0 and out["identifiable"] is False
    assert any("m" in w and "--fix" in w for w in out["warnings"])
    # a perfect fit on a scaled copy: c/m and k/m right, the scale not
    p = out["params"]
    assert p["c"] / p["m"] == pytest.approx(2500 / 450, rel=1e-5)
    assert p["k"] / p["m"] == pytest.approx(40000 / 450, rel=1e-5)
    r = run("identify", "--model", "quarter1", "--input", str(csv), "--fix", "m=450", "--json")
    out = json.loads(r.stdout)
    assert out["identifiable"] is True
    assert abs(out["params"]["c"] / 2500 - 1) < 1e-6 and abs(out["params"]["k"] / 40000 - 1) < 1e-6


@pytest.mark.parametrize("content, needle", [
    ("t,x1\n0,0\n0,0.1\n", "increasing time"),
    ("t,x1\n0,0\n0.1,abc\n", "column 'x1'"),
    ("x1,x2\n0,0\n", "no 't' column"),
    ("", "empty file"),
    ("t,x1\n0,0\n0.1\n", "expected 2 cells"),
    ("t,foo\n0,1\n0.1,2\n", "no measured channel"),
    ("t,x1\n0,0\n0.1,inf\n", "finite"),
])
def test_bad_csv_is_one_error_line_exit_2(tmp_path: Path, content: str, needle: str) -> None:
    f = tmp_path / "bad.csv"
    f.write_text(content)
    r = run("identify", "--model", "quarter2", "--input", str(f), "--json")
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], r.stderr
    assert str(f) in lines[0] and "Traceback" not in r.stderr


@pytest.mark.parametrize("args, needle", [
    (["identify", "--model", "quarter9", "--input", "x.csv"], "invalid choice"),
    (["identify", "--model", "quarter2", "--input", "missing.csv"], "no such file"),
    (["identify", "--model", "quarter2", "--input", "x.csv", "--fix", "zz=1"], "no parameter 'zz'"),
    (["identify", "--model", "quarter2", "--input", "x.csv", "--fix", "m1"], "expected NAME=VALUE"),
    (["identify", "--model", "quarter2", "--input", "x.xyz"], "unknown input format"),
])
def test_bad_usage_exit_2(tmp_path: Path, args: list[str], needle: str) -> None:
    (tmp_path / "x.csv").write_text("t,x1\n0,0\n0.1,0.2\n")
    r = run(*args, cwd=tmp_path)
    assert r.returncode == 2
    assert r.stderr.strip().startswith("error:") and needle in r.stderr and "Traceback" not in r.stderr


def test_unknown_columns_and_gaps_are_tolerated(tmp_path: Path, bump_csv: Path) -> None:
    lines = bump_csv.read_text().splitlines()
    header = lines[0] + ",comment"
    body = [ln + ",0" for ln in lines[1:]]
    cells = body[500].split(",")
    cells[3] = ""  # a missing x1 sample
    body[500] = ",".join(cells)
    f = tmp_path / "gappy.csv"
    f.write_text("\n".join([header] + body) + "\n")
    r = run("identify", "--model", "quarter2", "--input", str(f), "--fix", "m1=275", "--fix", "m2=27",
            "--init", "c1=1120", "--init", "k1=150000", "--init", "c2=3100", "--init", "k2=310000", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert any("comment" in w for w in out["warnings"])
    assert abs(out["params"]["k1"] / 150000 - 1) < 1e-4


def test_debug_shows_traceback(tmp_path: Path) -> None:
    r = run("--debug", "identify", "--model", "quarter2", "--input", str(tmp_path / "none.csv"))
    assert r.returncode != 0 and "Traceback" in r.stderr


def test_help_does_not_import_heavy_packages() -> None:
    """Fast start: listing commands must not pull in python-can, cantools, matplotlib, filterpy."""
    code = ("import sys; from suspid.cli import build_parser; build_parser(); "
            "heavy = [m for m in ('can', 'cantools', 'matplotlib', 'filterpy', 'asammdf') if m in sys.modules]; "
            "print(','.join(heavy))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == ""


def test_identify_on_a_csv_does_not_import_the_can_stack(tmp_path: Path) -> None:
    """A CSV is identified without python-can, cantools or asammdf (their import is ~0.4 s);
    the same process then still reads a CAN log, which does load them."""
    csv = tmp_path / "bump.csv"
    assert run("simulate", "--model", "quarter2", "--scenario", "bump", "--duration", "1",
               "--fs", "200", "--out", str(csv)).returncode == 0
    code = ("import sys, io, contextlib; from suspid.cli import main; buf = io.StringIO()\n"
            "with contextlib.redirect_stdout(buf):\n"
            f"    rc = main(['identify', '--model', 'quarter2', '--input', {str(csv)!r}, "
            "'--fix', 'm1=275', '--fix', 'm2=27', '--json'])\n"
            "heavy = [m for m in ('can', 'cantools', 'asammdf') if m in sys.modules]\n"
            "print(rc, ','.join(heavy) or '-')\n"
            "from estimator.identify.inputs import read_input; from suspid.models import get_model\n"
            "try:\n"
            f"    read_input({str(tmp_path / 'x.blf')!r}, get_model('quarter2'))\n"
            "except Exception as exc:\n"
            "    print(type(exc).__name__, 'cantools' in sys.modules and 'can' in sys.modules)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    first, second = r.stdout.strip().splitlines()
    assert first == "0 -"
    assert second == "InputError True"   # the missing .blf is read as a CAN log


@pytest.mark.slow
def test_no_road_and_no_decay_is_called_out(tmp_path: Path) -> None:
    """Driving vibration without a road column cannot be a free response: say so."""
    sim = tmp_path / "road.csv"
    assert run("simulate", "--model", "quarter2", "--scenario", "iso8608", "--duration", "6",
               "--fs", "200", "--out", str(sim)).returncode == 0
    lines = sim.read_text().splitlines()
    head = lines[0].split(",")
    keep = [i for i, h in enumerate(head) if h in ("t", "x1", "x2")]
    noroad = tmp_path / "noroad.csv"
    noroad.write_text("\n".join(",".join(l.split(",")[i] for i in keep) for l in lines) + "\n")
    r = run("identify", "--model", "quarter2", "--input", str(noroad), "--fix", "m1=300",
            "--fix", "m2=40", "--json", "--maxfev", "50")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["road"] == "unknown"      # driving data: the road is unknown, and it is said
    assert any("does not decay" in w and "--road unknown" in w for w in out["warnings"])
    r = run("identify", "--model", "quarter2", "--input", str(noroad), "--fix", "m1=300",
            "--fix", "m2=40", "--json", "--maxfev", "50", "--road", "zero")
    out = json.loads(r.stdout)           # forced to a free response: the output-error fit says why
    assert out["road"] == "zero"
    assert any("does not decay" in w and "--output-only" in w for w in out["warnings"])
    free = tmp_path / "free.csv"                     # a release test decays: no such warning
    assert run("simulate", "--model", "quarter2", "--scenario", "initial", "--duration", "5",
               "--out", str(free)).returncode == 0
    r = run("identify", "--model", "quarter2", "--input", str(free), "--fix", "m1=300",
            "--fix", "m2=40", "--json")
    out = json.loads(r.stdout)
    assert out["road"] in ("measured", "zero")
    assert not any("does not decay" in w for w in out["warnings"])


def test_subcommand_start_imports_only_its_own_module() -> None:
    """``suspid monitor ...`` registers (and imports) the monitor subcommand alone."""
    code = ("import sys; from suspid.cli import main, _subcommand; "
            "assert _subcommand(['--debug', 'monitor', '--model', 'x']) == 'monitor'; "
            "assert _subcommand(['--debug']) is None and _subcommand(['nope']) is None; "
            "main(['doe', '--help'])")
    r = subprocess.run([sys.executable, "-c", code + "\n"], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0 and "suspid doe" in r.stdout, r.stderr
    code = ("import sys; from suspid.cli import main\n"
            "try:\n    main(['simulate', '--help'])\nexcept SystemExit:\n    pass\n"
            "print(','.join(sorted(m for m in sys.modules if m.startswith('suspid.cli.') "
            "and not m.startswith('suspid.cli._'))))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == "suspid.cli.simulate"


def test_listing_matches_each_subcommand_module() -> None:
    """`suspid --help` lists from a table; each module's own parser says the same words."""
    import argparse
    import importlib

    from suspid.cli import SUBCOMMANDS

    for name, summary in SUBCOMMANDS.items():
        sub = argparse.ArgumentParser().add_subparsers()
        importlib.import_module(f"suspid.cli.{name}").add_parser(sub)
        helps = {a.dest: a.help for a in sub._choices_actions}
        assert helps == {name: summary}, name


@pytest.mark.parametrize("command", ["identify", "diagnose", "monitor", "fleet", "compare", "simulate"])
def test_model_help_names_every_model(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    """``--model`` accepted full7 but its help listed quarter1, quarter2 and half4 only."""
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    line = text[text.index("suspension model:"):]
    for name in MODELS:
        assert f"{name} (" in line or f"{name}," in line or line.startswith(f"suspension model: {name}"), name
    assert "full7 (7 DOF full car)" in line


def test_maxfev_help_matches_the_reported_nfev(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``identify --maxfev 100`` reports nfev 200 (two starts, each its own budget); its
    help said "budget over all restarts" only."""
    csv = tmp_path / "b.csv"
    assert main(["simulate", "--model", "quarter2", "--scenario", "bump", "--duration", "1",
                 "--fs", "200", "--noise", "0.01", "--out", str(csv)]) == 0
    capsys.readouterr()
    assert main(["identify", "--model", "quarter2", "--input", str(csv), "--maxfev", "100",
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    runs = [s for s in out["starts"] if not s.get("skipped")]
    assert len(runs) >= 2 and 100 < out["nfev"] <= 100 * len(runs) * 2   # (twin fits included)
    with pytest.raises(SystemExit):
        main(["identify", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "each have their own, and nfev reports their sum" in text


def test_a_length_in_another_unit_is_named(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """``--fix a1=1200`` (mm for m) on the half car: the output names the value, the range
    and the unit slip; the model's own geometry raises no such warning."""
    csv = tmp_path / "h4.csv"
    assert main(["simulate", "--model", "half4", "--scenario", "bump", "--duration", "1",
                 "--fs", "200", "--out", str(csv)]) == 0
    capsys.readouterr()
    base = ["identify", "--model", "half4", "--input", str(csv), "--fix", "m=1200",
            "--fix", "I=1500", "--fix", "m1=40", "--fix", "m2=40", "--fix", "a2=1.4",
            "--maxfev", "20", "--config", write_config(tmp_path, "[fit]\ndata_start = false\n"),
            "--json"]
    assert main(base + ["--fix", "a1=1200"]) == 0
    cap = capsys.readouterr()
    warns = json.loads(cap.out)["warnings"]
    assert warns[0].startswith("--fix a1=1200 m (") and "outside 0.01..20 m" in warns[0]
    assert "mm" in warns[0] and "warning: --fix a1=1200 m" in cap.err
    assert main(base + ["--fix", "a1=1.2"]) == 0
    assert not any("outside" in w for w in json.loads(capsys.readouterr().out)["warnings"])


def test_every_model_default_and_design_truth_is_plausible() -> None:
    """No documented default nor any value of the seed's designs (L16/L27 levels) is called
    implausible: the check names unit slips, not the vehicles the project studies."""
    for name in MODELS:
        model = get_model(name)
        assert implausible_values(model, model.defaults(), "--fix") == [], name
        if name in ("quarter1", "quarter2", "half4"):
            for exp in experiments(model):
                assert implausible_values(model, exp.truth, "--fix") == [], (name, exp)
