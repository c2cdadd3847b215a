"""tests/doe: OpenBLAS single-threaded (small matrices; threads only cost on shared cores)."""
from __future__ import annotations

import pytest

from threadpoolctl import threadpool_limits


@pytest.fixture(scope="session", autouse=True)
def _single_thread_blas() -> None:
    threadpool_limits(limits=1, user_api="blas")
