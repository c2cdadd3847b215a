"""Fuzzing the measurement CSV reader: any input is either read or rejected with InputError."""
from __future__ import annotations

import math
import tracemalloc
from pathlib import Path

import can
import numpy as np
import pytest
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


@pytest.mark.slow
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


def test_trailing_separator_is_an_empty_last_column(tmp_path: Path) -> None:
    """Spreadsheet exports end lines with a separator: on the rows, on the header or on
    both. Such a file reads as without it; an unnamed column that holds values is ignored
    with a warning naming its position, and a row still needs every named cell."""
    m1 = get_model("quarter1")
    want = np.array([1.0, 2.0, 3.0])
    for text in ("t,x\n0,1,\n0.1,2,\n0.2,3,\n",      # rows only
                 "t,x,\n0,1\n0.1,2\n0.2,3\n",         # header only
                 "t,x,\n0,1,\n0.1,2,\n0.2,3,\n",      # both
                 "t,x\r\n0,1,,\r\n0.1,2,\r\n0.2,3\r\n"):  # CRLF, ragged
        meas = read_measurement(_write(tmp_path, text), m1)
        np.testing.assert_array_equal(meas.measured["x"], want)
        assert meas.warnings == []
    meas = read_measurement(_write(tmp_path, "t,x,,\n0,1,5\n0.1,2,,\n0.2,3\n"), m1)
    np.testing.assert_array_equal(meas.measured["x"], want)
    assert meas.warnings == [f"{tmp_path / 'fuzz.csv'}: ignoring the values in columns 3-4 "
                             "(no name in the header)"]
    meas = read_measurement(_write(tmp_path, "t,,x\n0,9,1\n0.1,,2\n0.2,1,3\n"), m1)
    assert "column 2 (no name)" in meas.warnings[0]
    for text, where in (("t,x\n0,1,7\n0.1,2\n", ":2: expected 2 cells, got 3"),
                        ("t,x,\n0\n0.1,2\n", ":2: expected 2 cells, got 1")):
        with pytest.raises(InputError, match=where):
            read_measurement(_write(tmp_path, text), m1)


@pytest.mark.parametrize("cell", ["1_000", "0.00_5", "\u0661\u0662", "\uff11"])
def test_python_only_number_spellings_are_rejected(tmp_path: Path, cell: str) -> None:
    """float() reads digit-group underscores and other scripts' digits; a CSV number is
    plain ASCII, so such a cell is named as not a number instead of read as one."""
    text = f"t,x\n0,1\n0.1,{cell}\n0.2,3\n"
    with pytest.raises(InputError, match=r":3: column 'x': expected a number"):
        read_measurement(_write(tmp_path, text), get_model("quarter1"))


def test_header_names_with_their_si_unit_are_read(tmp_path: Path) -> None:
    """A logger's export annotates names with units: ``t [s]``, ``x1_dot (m/s)`` are the
    contract's columns (were: "no 't' column" for the first, the second silently ignored)."""
    body = "0,0,0.01,0.1,1\n0.005,0.001,0.011,0.12,1.5\n0.01,0.002,0.012,0.13,2\n"
    p = _write(tmp_path, "t [s],r (m),x1 [m],x1_dot (m/s),x2_ddot [m/s^2]\n" + body)
    m = read_measurement(p, Q2)
    assert set(m.measured) == {"x1", "x1_dot", "x2_ddot"} and set(m.road) == {"r"}
    assert m.warnings == []
    assert np.allclose(m.measured["x1_dot"], [0.1, 0.12, 0.13])
    assert np.allclose(m.t, [0, 0.005, 0.01])
    # spellings of m/s^2 and angles in rad (half4's pitch)
    h4 = read_measurement(_write(tmp_path, "t [s],x (m),delta [rad],x_ddot [m/s²]\n0,1,2,3\n1,1,2,3\n"),
                          get_model("half4"))
    assert set(h4.measured) == {"x", "delta", "x_ddot"} and h4.warnings == []


def test_header_names_with_other_units_are_named_not_converted(tmp_path: Path) -> None:
    body = "0,1,2\n0.005,1,2\n0.01,1,2\n"
    m = read_measurement(_write(tmp_path, "t [s],x1 [mm],x2 (m)\n" + body), Q2)
    assert set(m.measured) == {"x2"}
    assert m.warnings == [f"{tmp_path / 'fuzz.csv'}: ignoring column 'x1 [mm]': x1 in 'mm', "
                          "expected m (SI; convert the column)"]
    with pytest.raises(InputError, match=r"fuzz\.csv:1: column 't \[ms\]': time in 'ms', expected s"):
        read_measurement(_write(tmp_path, "t [ms],x1 [m]\n" + "0,1\n5,1\n"), Q2)
    with pytest.raises(InputError, match=r"no measured channel .*; column 'x1 \[mm\]' is x1 in 'mm', "
                                         r"expected m$"):
        read_measurement(_write(tmp_path, "t,x1 [mm]\n0,1\n1,1\n"), Q2)
    # a name that is no column of the model keeps the unknown-column warning
    other = read_measurement(_write(tmp_path, "t,x1,rpm [1/min]\n0,1,2\n1,1,2\n"), Q2)
    assert other.warnings == [f"{tmp_path / 'fuzz.csv'}: ignoring column(s) not used by model "
                              "quarter2: rpm [1/min]"]
    # the vehicle's speed is read (in m/s, the fleet's distance), and named in another unit
    speed = read_measurement(_write(tmp_path, "t,x1,speed [km/h]\n0,1,2\n1,1,2\n"), Q2)
    assert speed.aux == {} and speed.warnings == [
        f"{tmp_path / 'fuzz.csv'}: ignoring column 'speed [km/h]': speed in 'km/h', expected m/s "
        "(SI; convert the column)"]
    assert read_measurement(_write(tmp_path, "t,x1,speed [m/s]\n0,1,2\n1,1,2\n"),
                            Q2).aux["speed"].tolist() == [2.0, 2.0]


def test_a_semicolon_separated_export_is_named(tmp_path: Path) -> None:
    """A spreadsheet's export with ';' (and decimal commas): the error says what the
    separator is (was: only "no 't' column ... (got t;x1)")."""
    with pytest.raises(InputError, match=r"fuzz\.csv:1: no 't' column in the header \(got t;x1\); "
                                         r"the header is separated by ';', expected commas"):
        read_measurement(_write(tmp_path, "t;x1\n0;0,001\n0,005;0,002\n"), Q2)
    with pytest.raises(InputError, match=r"^[^;]*\(got time, x1\)$"):
        read_measurement(_write(tmp_path, "time,x1\n0,1\n1,2\n"), Q2)


def test_a_python_can_csv_log_is_named_with_its_conversion(tmp_path: Path) -> None:
    """python-can's own CSV log format (``can.Logger("x.csv")``): CAN frames, not
    measurements; the error says so and how to convert it (was: only "no 't' column")."""
    p = tmp_path / "frames.csv"
    with can.Logger(str(p)) as w:
        w.on_message_received(can.Message(timestamp=0.5, arbitration_id=0x110,
                                          is_extended_id=False, data=bytes(8)))
    with pytest.raises(InputError) as err:
        read_measurement(p, Q2)
    msg = str(err.value)
    assert msg.startswith(f"{p}:1: no 't' column in the header (got timestamp, arbitration_id")
    assert msg.endswith(f"this is a CAN log in python-can's CSV format, not a measurement CSV: "
                        f"convert it to a CAN log, e.g. python -m can.logconvert {p} "
                        f"{tmp_path / 'frames.blf'}")


def test_a_road_gap_is_filled_from_the_road_velocity(tmp_path: Path) -> None:
    """A 0.2 s hole in `r` over a bump while `r_dot` is complete: `r` is integrated from
    `r_dot` across it (was: joined by a straight line, and identify reported `success: true`
    with c2 27x and m2 8x the truth); without `r_dot` the straight line stays, and the
    warning says the fit follows that guess."""
    t = np.arange(0.0, 3.0, 0.002)
    r = np.where((t > 0.5) & (t < 1.0), 0.05 * (1 - np.cos(2 * np.pi * (t - 0.5) / 0.5)), 0.0)
    r_dot = np.gradient(r, t)
    hole = (t >= 0.6) & (t < 0.8)
    rows = ["t,r,r_dot,x1"] + [f"{a:.17g},{'' if g else f'{b:.17g}'},{c:.17g},0" for a, b, c, g in
                               zip(t, r, r_dot, hole)]
    m = read_measurement(_write(tmp_path, "\n".join(rows) + "\n"), Q2)
    assert np.max(np.abs(m.road["r"] - r)) < 1e-4
    assert any("100 missing samples integrated from r_dot" in w for w in m.warnings)
    rows = ["t,r,x1"] + [f"{a:.17g},{'' if g else f'{b:.17g}'},0" for a, b, g in zip(t, r, hole)]
    m = read_measurement(_write(tmp_path, "\n".join(rows) + "\n"), Q2)
    assert np.max(np.abs(m.road["r"] - r)) > 0.01
    assert any("linear interpolation" in w and "follows the guess" in w for w in m.warnings)
