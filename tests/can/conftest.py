"""Fixtures of the CAN-layer tests: the DBC, a simulated measurement CSV and its encoded logs."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from suspid.can.dbc import load_dbc
from suspid.excitation import make_scenario
from suspid.io.csvio import write_measurement
from suspid.models import get_model
from suspid.simulate import simulate

#: ../shared/realdata beside the repository root
REALDATA = Path(__file__).parents[2].parent / "shared" / "realdata"

#: DBC resolution of each quarter-car channel (half a step is the quantization bound)
Q2_STEP = {"x1": 1e-5, "x2": 1e-5, "x1_dot": 1e-4, "x2_dot": 2e-4, "x1_ddot": 0.005,
           "x2_ddot": 0.02, "r": 1e-5, "r_dot": 5e-4}


@pytest.fixture(scope="session")
def db():
    return load_dbc()


@pytest.fixture(scope="session")
def q2_csv(tmp_path_factory) -> Path:
    """A 2 s quarter2 bump record at 500 Hz with every channel, as a measurement CSV."""
    m = get_model("quarter2")
    t, road, x0 = make_scenario(m, "bump", duration=2.0, fs=500.0, t0=0.2)
    out = simulate(m, m.defaults(), t, road, x0)
    path = tmp_path_factory.mktemp("q2") / "q2.csv"
    write_measurement(path, t, {k: out[k] for k in Q2_STEP})
    return path


@pytest.fixture(scope="session")
def q2_log(q2_csv) -> Path:
    """``q2_csv`` encoded to a candump log through the CLI."""
    from suspid.cli import main

    out = q2_csv.with_suffix(".log")
    if main(["encode", "--input", str(q2_csv), "--out", str(out)]) != 0:
        raise RuntimeError("suspid encode failed")
    return out


@pytest.fixture
def realdata() -> Path:
    if not REALDATA.is_dir():
        pytest.skip(f"real recordings not found at {REALDATA} (../shared/realdata beside the repo)")
    return REALDATA


def max_err(a: np.ndarray, b: np.ndarray) -> float:
    ok = ~np.isnan(a) & ~np.isnan(b)
    return float(np.max(np.abs(a[ok] - b[ok])))
