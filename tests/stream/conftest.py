"""Shared streams of the streaming-estimator tests (generated once per session)."""
from __future__ import annotations

import pytest

from estimator.stream.scenarios import Stream, damper_wear
from suspid.models import get_model

#: the must-show stream: c1 falls linearly from 1500 to 750 N s/m between 10 s and 100 s,
#: crossing 70 % of nominal (1050 N s/m) at 64 s -- the damper-wear scenario, shortened
WEAR = dict(duration=100.0, fs=500.0, wear_start=10.0, c_end_fraction=0.5, seed=3)


@pytest.fixture(scope="session")
def wear_stream() -> Stream:
    return damper_wear(get_model("quarter2"), **WEAR)


@pytest.fixture(scope="session")
def quarter2():
    return get_model("quarter2")
