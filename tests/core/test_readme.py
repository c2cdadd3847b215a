"""The README's example commands, run verbatim as a new user runs them from a fresh clone's
root (beside ``../shared``, as ``.ci/run`` is), and the results they claim.

Each command line of the README's ``Examples`` and ``A fleet`` blocks (continuations
joined, comments dropped) runs as ``python -m suspid ARGS`` with its arguments unchanged, in
a temporary directory that stands where a clone's root stands: ``../shared`` beside it is
the shared folder, and the files the commands write stay out of the checkout. Only commands
that need a live bus would be skipped (none of these does); the one reading
``../shared/realdata`` is skipped where that folder is absent.
"""
from __future__ import annotations

import json
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from ..conftest import REPO, SHARED, TABLE1, suspid_env

README = REPO / "README.md"


def readme_commands(section: str) -> list[list[str]]:
    """The ``suspid`` command lines of the first fenced bash block under ``### SECTION``."""
    text = README.read_text(encoding="utf-8")
    body = text.split(f"### {section}\n", 1)[1]
    block = body.split("```bash\n", 1)[1].split("```", 1)[0]
    joined = block.replace("\\\n", " ")
    cmds = [shlex.split(line, comments=True) for line in joined.splitlines()]
    return [c for c in cmds if c and c[0] == "suspid"]


def _live(cmd: list[str]) -> bool:
    return "--interface" in cmd or "--channel" in cmd


@pytest.fixture
def root(tmp_path: Path) -> Path:
    """A clone's root: ``../shared`` beside it is the shared folder."""
    (tmp_path / "shared").symlink_to(SHARED, target_is_directory=True)
    r = tmp_path / "suspid"
    r.mkdir()
    return r


def _run(cmd: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    proc = subprocess.run([sys.executable, "-m", "suspid", *cmd[1:]], cwd=cwd, env=suspid_env(),
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"{shlex.join(cmd)}\n{proc.stderr}"
    assert "Traceback" not in proc.stderr
    return proc


def test_the_readme_has_the_examples() -> None:
    ex = readme_commands("Examples")
    assert [c[1] for c in ex] == ["simulate", "identify", "encode", "identify", "monitor",
                                  "simulate", "identify", "diagnose", "doe"]
    assert [c[1] for c in readme_commands("A fleet")] == ["fleet", "fleet"]
    assert not any(_live(c) for c in ex)
    # the data of the real-logger example is named from the clone's root
    assert any(a.startswith("../shared/realdata/") for c in ex for a in c)


@pytest.mark.slow
def test_readme_examples_run_verbatim(root: Path) -> None:
    """Every example but the real logger's and the study (tests below), in order; the
    values the comments claim."""
    outs = {}
    for i, cmd in enumerate(readme_commands("Examples")):
        if cmd[1] == "doe" or any("../shared/" in a for a in cmd):
            continue
        outs[i] = _run(cmd, root)
    # identify from half the truth, masses known: c1, k1, c2, k2 to ~1e-10
    fit = json.loads(outs[1].stdout)
    for k in ("c1", "k1", "c2", "k2"):
        assert fit["params"][k] == pytest.approx(TABLE1[k], rel=1e-8), k
    assert (root / "bump.png").is_file() and (root / "fit.png").is_file()
    blf = json.loads(outs[3].stdout)
    assert blf["frames"]["accepted"] > 0 and blf["success"]
    # production sensors: road unknown, c1 and k1 within 0.2 %, c2 and k2 undetermined
    drive = json.loads(outs[6].stdout)
    assert drive["road"] == "unknown" and set(drive["undetermined"]) == {"c2", "k2"}
    assert drive["params"]["c1"] == pytest.approx(1500.0, rel=2e-3)
    assert drive["params"]["k1"] == pytest.approx(20000.0, rel=2e-3)
    assert json.loads(outs[7].stdout)["evidence"]


@pytest.mark.slow
def test_readme_real_logger_example(root: Path) -> None:
    if not (SHARED / "realdata" / "canedge-imu").is_dir():
        pytest.skip(f"real recordings not found at {SHARED / 'realdata'}")
    (cmd,) = [c for c in readme_commands("Examples") if any("../shared/" in a for a in c)]
    lines = [json.loads(x) for x in _run(cmd, root).stdout.splitlines()]
    est = [d for d in lines if d["type"] == "estimate"]
    assert len(est) >= 15 and lines[-1]["type"] == "summary"


@pytest.mark.slow
def test_readme_doe_example(root: Path) -> None:
    """The seed's half-car study with the frobenius cost from 0.5x: 27/27 (~45 s)."""
    (cmd,) = [c for c in readme_commands("Examples") if c[1] == "doe"]
    out = json.loads(_run(cmd, root).stdout)
    assert (out["successes"], out["total"]) == (27, 27)


@pytest.mark.slow
def test_readme_fleet_example(root: Path) -> None:
    """The fleet block on a folder of two vehicles' drives, as the README describes it."""
    csv = root / "d.csv"
    for k, (van, seed) in enumerate([("VAN-07", 1), ("VAN-07", 2), ("VAN-12", 3)]):
        (root / "fleet" / van).mkdir(parents=True, exist_ok=True)
        _run(["suspid", "simulate", "--model", "quarter2", "--scenario", "iso8608", "--duration",
              "10", "--fs", "200", "--noise", "0.01", "--seed", str(seed), "--out", str(csv)], root)
        _run(["suspid", "encode", "--input", str(csv), "--out",
              str(root / "fleet" / van / f"2026-11-0{k + 1}.blf")], root)
    first, second = readme_commands("A fleet")
    out = json.loads(_run(first, root).stdout)
    assert (root / "fleet.sqlite").is_file() and (root / "report").is_dir()
    assert sorted(v["vehicle"] for v in out["vehicles"]) == ["VAN-07", "VAN-12"]
    assert [d["status"] for d in out["drives"]] == ["ok"] * 3 and out["new"] == 3
    again = json.loads(_run(second, root).stdout)   # from the history alone
    assert sorted(v["vehicle"] for v in again["vehicles"]) == ["VAN-07", "VAN-12"]
