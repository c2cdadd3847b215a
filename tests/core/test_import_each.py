"""Every project module imports on its own, first (a cycle hidden by import order fails here).

import-linter checks the layers between packages; a cycle inside one package (a module that
imports a package whose ``__init__`` imports the module back) only shows when that module is
the first one imported. Each module is imported in a fresh set of project modules.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = r"""
import importlib, pkgutil, sys, traceback
roots = ("suspid", "estimator", "firmware_sim")
names = []
for root in roots:
    pkg = importlib.import_module(root)
    names.append(root)
    names += [m.name for m in pkgutil.walk_packages(pkg.__path__, root + ".")
              if not m.name.endswith(".__main__")]  # runs the CLI
bad = []
for name in names:
    for k in [k for k in sys.modules if k.split(".")[0] in roots]:
        del sys.modules[k]
    try:
        importlib.import_module(name)
    except Exception as exc:  # report every failing module, not just the first
        bad.append(f"{name}: {type(exc).__name__}: {exc}")
print(len(names))
print("\n".join(bad))
"""


@pytest.mark.slow
def test_every_module_imports_first() -> None:
    out = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, capture_output=True,
                         text=True, timeout=600, env={"MPLBACKEND": "Agg", "PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.strip().splitlines()
    assert int(lines[0]) > 80  # every package walked
    assert lines[1:] == [], "\n".join(lines[1:])
