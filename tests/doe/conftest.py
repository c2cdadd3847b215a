"""tests/doe: OpenBLAS single-threaded (small matrices; threads only cost on shared cores)."""
from __future__ import annotations

import pytest

from estimator.doe.blas import single_thread_blas


@pytest.fixture(scope="session", autouse=True)
def _single_thread_blas() -> None:
    single_thread_blas()
