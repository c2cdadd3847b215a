"""``suspid X --help`` for every subcommand: exit status 0, and no heavy library loaded.

The help is meant to answer at once (``tools/bench_help.py`` times it); what these tests
pin down is its cause: building a subcommand's parser imports neither the estimator's
fitting code nor scipy.optimize, matplotlib, python-can, cantools, asammdf or Dask.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from suspid.cli import SUBCOMMANDS

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
HEAVY = ("scipy.optimize", "scipy.signal", "matplotlib", "can", "cantools", "asammdf", "dask",
         "distributed", "filterpy", "estimator.identify", "estimator.stream.pipeline")


@pytest.mark.parametrize("command", list(SUBCOMMANDS))
def test_help_exits_0(command: str) -> None:
    r = subprocess.run([sys.executable, "-m", "suspid", command, "--help"], cwd=ROOT, env=ENV,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(f"usage: suspid {command}")


@pytest.mark.parametrize("command", list(SUBCOMMANDS))
def test_help_loads_no_heavy_library(command: str) -> None:
    code = ("import sys\nfrom suspid.cli import main\n"
            f"try:\n    main([{command!r}, '--help'])\nexcept SystemExit:\n    pass\n"
            f"print('LOADED', ','.join(m for m in {HEAVY!r} if m in sys.modules))\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=ENV, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[-1] == "LOADED ", f"{command} --help loaded heavy modules"
