"""Fuzzing the measurement CSV reader: any input is either read or rejected with InputError."""
from __future__ import annotations

import math
import tracemalloc
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from suspid.errors import InputError
from suspid.io.csvio import read_measurement
from suspid.models import get_model

Q2 = get_model("quarter2")
CELLS = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr), st.just(""),
                  st.text(alphabet="0123456789.-eE+x ,\"", max_size=6))
HEADERS = st.lists(st.sampled_from(["t", "x1", "x2", "r", "r_dot", "x1_dot", "junk", "x1_ddot"]),
                   min_size=1, max_size=5)


def _write(tmp: Path, text: str | bytes) -> Path:
    p = tmp / "fuzz.csv"
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_text(text)
    return p


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(header=HEADERS, rows=st.lists(st.lists(CELLS, min_size=0, max_size=6), max_size=8))
def test_structured_fuzz_never_crashes(tmp_path: Path, header: list[str], rows: list[list[str]]) -> None:
    text = ",".join(header) + "\n" + "\n".join(",".join(r) for r in rows) + "\n"
    try:
        m = read_measurement(_write(tmp_path, text), Q2)
    except InputError as exc:
        msg = str(exc)
        assert "\n" not in msg and "fuzz.csv" in msg
        return
    assert np.all(np.diff(m.t) > 0) and m.measured
    for arr in list(m.measured.values()) + list(m.road.values()):
        assert arr.shape == m.t.shape
        assert not np.isinf(arr).any()


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(blob=st.binary(max_size=300))
def test_binary_garbage_is_rejected_cleanly(tmp_path: Path, blob: bytes) -> None:
    try:
        read_measurement(_write(tmp_path, blob), Q2)
    except InputError as exc:
        assert "\n" not in str(exc)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(t=st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=2, max_size=30))
def test_time_must_strictly_increase(tmp_path: Path, t: list[float]) -> None:
    text = "t,x1\n" + "".join(f"{v!r},0.0\n" for v in t)
    ok = all(b > a for a, b in zip(t, t[1:]))
    try:
        m = read_measurement(_write(tmp_path, text), Q2)
        assert ok and np.array_equal(m.t, np.array(t))
    except InputError as exc:
        assert not ok and "increasing time" in str(exc)


def test_large_file_is_read_in_compact_columns(tmp_path: Path) -> None:
    n = 200_000
    t = np.arange(n) / 1000.0
    p = tmp_path / "big.csv"
    with p.open("w") as fh:
        fh.write("t,x1,x2\n")
        for k in range(0, n, 10000):
            blk = np.column_stack([t[k:k + 10000], np.sin(t[k:k + 10000]), np.cos(t[k:k + 10000])])
            np.savetxt(fh, blk, delimiter=",", fmt="%.9g")
    tracemalloc.start()
    try:
        m = read_measurement(p, Q2)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert m.t.size == n and math.isclose(m.measured["x1"][-1], math.sin(t[-1]), rel_tol=1e-6)
    # 3 columns x 8 B per value, held twice at most (array('d') then numpy), plus the
    # csv reader's one row: no per-row Python objects (which would be ~100 B per cell)
    values = 3 * n * 8
    assert peak < 2.5 * values, (peak, values)
