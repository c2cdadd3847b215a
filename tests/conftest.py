"""Shared fixtures: the seed's parameter sets and paths."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import settings

# Deterministic fuzzing in every run (CI included): the examples depend only on the
# hypothesis version, so a red CI is reproducible and a green one is not luck.
settings.register_profile("suspid", derandomize=True, deadline=None, database=None)
settings.load_profile("suspid")

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"

#: seed Table 1 (Sharma and Saluja): quarter-car parameters, SI
TABLE1 = dict(m1=275.0, k1=150000.0, c1=1120.0, m2=27.0, k2=310000.0, c2=3100.0)


@pytest.fixture
def table1() -> dict[str, float]:
    return dict(TABLE1)


@pytest.fixture
def realdata() -> Path:
    p = SHARED / "realdata"
    if not p.is_dir():
        pytest.skip(f"real recordings not found at {p} (../shared/realdata beside the repo)")
    return p


def suspid_env() -> dict[str, str]:
    """Environment for a ``python -m suspid`` subprocess that imports this checkout."""
    return dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))


def start_slcan_node(*node_args: str) -> tuple[subprocess.Popen[str], str]:
    """Start ``suspid node --interface slcan --channel pty NODE_ARGS`` in a subprocess.

    Returns the process and the pseudo-terminal path it printed as its first line (the
    contract's ``pty: /dev/pts/N``); the caller ends the process.
    """
    node = subprocess.Popen(
        [sys.executable, "-m", "suspid", "node", "--interface", "slcan", "--channel", "pty",
         *node_args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env=suspid_env(), cwd=REPO)
    assert node.stdout is not None and node.stderr is not None
    first = node.stdout.readline()
    if not first.startswith("pty: /dev/"):
        node.kill()
        raise AssertionError(f"node printed {first!r}, expected 'pty: /dev/...': {node.stderr.read()}")
    return node, first.split(":", 1)[1].strip()


def write_config(directory: Path, text: str, name: str = "suspid.toml") -> str:
    """Write a ``--config`` TOML file ``directory/name`` holding ``text``; its path."""
    path = Path(directory) / name
    path.write_text(text, encoding="utf-8")
    return str(path)
