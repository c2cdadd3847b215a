"""Logs and DBCs as other tools write them: Vector ASC options, users' multiplexed DBCs."""
from __future__ import annotations

import re
from decimal import Decimal
from pathlib import Path

import can
import cantools
import numpy as np
import pytest

from estimator.decode import load_log_as_measurement
from suspid.can.logs import ReadStats, read_log
from suspid.cli import main
from suspid.io.csvio import read_measurement
from suspid.models import get_model

from tests.can.conftest import Q2_STEP

T0 = 1764183653.123457


def _to_relative(text: str) -> str:
    """An absolute-time ASC as CANalyzer writes it with relative timestamps: every timed
    line carries the time since the previous timed line (from the trigger block)."""
    out = []
    prev: Decimal | None = None
    for line in text.splitlines():
        m = re.match(r"(\s*)(\d+\.\d+)(\s.*)$", line)
        if m is None:
            out.append(line.replace("timestamps absolute", "timestamps relative"))
            continue
        t = Decimal(m.group(2))
        out.append(f"{m.group(1)}{t - (prev if prev is not None else Decimal(0)):f}{m.group(3)}")
        prev = t
    return "\n".join(out) + "\n"


def test_asc_with_relative_timestamps_reads_the_absolute_times(q2_csv, tmp_path):
    absolute = tmp_path / "abs.asc"
    assert main(["encode", "--input", str(q2_csv), "--out", str(absolute), "--t0", str(T0)]) == 0
    lines = absolute.read_text().splitlines()
    # a timed event python-can skips (a chip status) must still count in the running sum
    k = next(i for i, line in enumerate(lines) if line.startswith(" 0.010457 "))
    lines.insert(k, " 0.009000 CAN 1 Status:chip status error active")
    absolute.write_text("\n".join(lines) + "\n")
    relative = tmp_path / "rel.asc"
    relative.write_text(_to_relative(absolute.read_text()))
    assert "timestamps relative" in relative.read_text()
    assert " 0.001457 1  100 " in relative.read_text()   # a delta (after the status)

    st = ReadStats()
    got = list(read_log(relative, st))
    want = list(read_log(absolute))
    assert st.malformed == 0 and len(got) == len(want) == 4025
    assert [m.timestamp for m in got] == [m.timestamp for m in want]   # bit for bit
    assert got[0].timestamp == pytest.approx(T0, abs=1e-6)
    assert [bytes(m.data) for m in got] == [bytes(m.data) for m in want]

    # decoded with the log's own clock: nothing goes back in time (was: 3024 frames
    # rejected as 'time' and no accepted data frame)
    meas, stats = load_log_as_measurement(relative, "quarter2", time_source="timestamp")
    assert stats["accepted"] == 4025 and sum(stats["rejected"].values()) == 0
    ref = read_measurement(q2_csv, get_model("quarter2"))
    np.testing.assert_allclose(meas.t - T0, ref.t, atol=1e-6)
    for ch, step in Q2_STEP.items():
        v = meas.measured.get(ch, meas.road.get(ch))
        assert v is not None and np.nanmax(np.abs(v - ref.measured.get(ch, ref.road.get(ch)))) \
            <= step / 2 + 1e-12


def test_asc_relative_times_restart_at_each_trigger_block(tmp_path):
    p = tmp_path / "two.asc"
    p.write_text("date Thu Nov 26 19:00:00.000 2026\nbase hex  timestamps relative\n"
                 "internal events logged\n"
                 "Begin Triggerblock Thu Nov 26 19:00:00.000 2026\n"
                 " 0.000000 Start of measurement\n"
                 " 0.500000 1  123             Rx   d 1 01\n"
                 " 0.250000 1  123             Rx   d 1 02\n"
                 "End TriggerBlock\n"
                 "Begin Triggerblock Thu Nov 26 19:01:00.000 2026\n"
                 " 0.000000 Start of measurement\n"
                 " 0.125000 1  123             Rx   d 1 03\n"
                 "End TriggerBlock\n")
    ts = [m.timestamp for m in read_log(p)]
    base = ts[0] - 0.5
    assert np.allclose(np.array(ts) - base, [0.5, 0.75, 60.125], atol=1e-6)


MUX_DBC = """VERSION ""

NS_ :

BS_:

BU_: ECU

BO_ 512 Chassis: 8 ECU
 SG_ Page M : 0|8@1+ (1,0) [0|255] "" ECU
 SG_ Height m0 : 15|16@0- (1e-05,0) [-0.32768|0.32767] "m" ECU
 SG_ Temp m1 : 15|16@0- (0.1,-40) [-40|200] "degC" ECU
 SG_ Road : 39|16@0- (1e-05,0) [-0.32768|0.32767] "m" ECU
"""


def _mux_log(tmp_path: Path, ref) -> tuple[Path, Path]:
    dbc = tmp_path / "mux.dbc"
    dbc.write_text(MUX_DBC)
    db = cantools.database.load_file(str(dbc))
    msg = db.get_message_by_name("Chassis")
    log = tmp_path / "mux.log"
    with can.Logger(str(log)) as w:
        for i, t in enumerate(ref.t):
            r = round(float(ref.road["r"][i]), 5)
            for page, dt, sig in ((0, 0.0, {"Height": round(float(ref.measured["x1"][i]), 5)}),
                                  (1, 0.0005, {"Temp": 25.0})):
                w.on_message_received(can.Message(
                    timestamp=float(t) + dt, arbitration_id=msg.frame_id, is_extended_id=False,
                    data=msg.encode({"Page": page, "Road": r, **sig})))
    return dbc, log


def test_a_multiplexed_signal_in_a_map_is_read_from_its_page_only(q2_csv, tmp_path):
    ref = read_measurement(q2_csv, get_model("quarter2"))
    dbc, log = _mux_log(tmp_path, ref)
    # the non-multiplexed signal of the message decodes as before
    meas, stats = load_log_as_measurement(log, "quarter2", dbc, ["x2=Chassis.Road"])
    assert stats["accepted"] == 2 * ref.t.size
    x2 = meas.measured["x2"]
    ok = ~np.isnan(x2)
    assert ok.sum() == 2 * ref.t.size   # both pages carry it
    sample = np.rint((meas.t[ok] - ref.t[0]) / (ref.t[1] - ref.t[0])).astype(int)
    assert np.max(np.abs(x2[ok] - ref.road["r"][sample])) <= 5e-6 + 1e-12
    # the multiplexed one was decoded from the Temp page too (0.065 m every other frame,
    # a 0.5 ms grid); now from the Height page only: every sample of the record, on its
    # 2 ms grid, and nothing of the temperature
    meas, stats = load_log_as_measurement(log, "quarter2", dbc, ["x1=Chassis.Height"])
    assert stats["accepted"] == 2 * ref.t.size and "unknown_page" not in stats
    assert meas.t.size == ref.t.size
    np.testing.assert_allclose(np.diff(meas.t), np.diff(ref.t), atol=1e-6)
    assert np.max(np.abs(meas.measured["x1"] - ref.measured["x1"])) <= 5e-6 + 1e-12


SAME_NAME_DBC = """VERSION ""

NS_ :

BS_:

BU_: ECU

BO_ 256 Body: 8 ECU
 SG_ Height : 0|16@1- (1e-05,0) [-0.32768|0.32767] "m" ECU

BO_ 2147483904 Body: 8 ECU
 SG_ Height : 0|16@1- (1e-05,0) [-0.32768|0.32767] "m" ECU
"""


def test_standard_and_extended_messages_of_one_name_are_told_apart(tmp_path, capsys):
    dbc = tmp_path / "same.dbc"
    dbc.write_text(SAME_NAME_DBC)
    db = cantools.database.load_file(str(dbc))
    log = tmp_path / "same.log"
    with can.Logger(str(log)) as w:
        for i in range(400):
            for ext, h in ((False, 0.01), (True, 0.02)):
                w.on_message_received(can.Message(
                    timestamp=0.002 * i, arbitration_id=0x100, is_extended_id=ext,
                    data=db.messages[int(ext)].encode({"Height": h})))
    # by frame ID: 0x100 is the standard frame, bit 31 (the DBC's notation) the extended
    # one (was: both decoded the extended frames, 0.02, through a lookup by name)
    for ref, want in (("0x100", 0.01), ("256", 0.01), ("0x80000100", 0.02),
                      ("2147483904", 0.02)):
        meas, stats = load_log_as_measurement(log, "quarter1", dbc, [f"x={ref}.Height"])
        assert stats["accepted"] == 400 and stats["ignored"] == 400, ref
        np.testing.assert_allclose(meas.measured["x"], want, atol=1e-12, err_msg=ref)
    # both at once: two sources, each its own frames
    meas, stats = load_log_as_measurement(
        log, "quarter2", dbc, ["x1=0x100.Height", "x2=0x80000100.Height"])
    assert stats["accepted"] == 800
    np.testing.assert_allclose(meas.measured["x1"], 0.01, atol=1e-12)
    np.testing.assert_allclose(meas.measured["x2"], 0.02, atol=1e-12)
    # by the shared name: one error line naming both IDs (was: the extended one, silently)
    capsys.readouterr()
    rc = main(["identify", "--model", "quarter1", "--input", str(log), "--dbc", str(dbc),
               "--map", "x=Body.Height", "--json"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1, err
    assert "message name 'Body' is ambiguous" in err[0]
    assert "0x100 (standard) and 0x80000100 (extended)" in err[0]


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf", ".trc", ".mf4"])
def test_encoded_times_not_from_zero_read_back_as_the_csv(tmp_path, suffix):
    """A CSV whose t starts at 0.5 s (not an epoch time): every format gives its times back
    (was: BLF 0.5 s short, python-can writing no start date below 1990 and its reader
    taking that as 0)."""
    csv = tmp_path / "late.csv"
    t = 0.5 + 0.002 * np.arange(50)
    csv.write_text("t,x1,x2\n" + "".join(f"{float(ti)!r},0.001,0.002\n" for ti in t))
    out = tmp_path / f"late{suffix}"
    assert main(["encode", "--input", str(csv), "--out", str(out)]) == 0
    got = np.array([m.timestamp for m in read_log(out) if m.arbitration_id == 0x100])
    np.testing.assert_allclose(got, t, rtol=0, atol=2e-7 if suffix == ".mf4" else 1e-9)


def test_blf_refuses_negative_times_in_one_line(tmp_path, capsys):
    csv = tmp_path / "neg.csv"
    csv.write_text("t,x1,x2\n-0.004,0.001,0.002\n-0.002,0.001,0.002\n0,0.001,0.002\n")
    out = tmp_path / "neg.blf"
    assert main(["encode", "--input", str(csv), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {out}: a BLF log stores times from 0 s on, got a frame at -0.004 s "
                   "(shift the times, e.g. with --t0)"]
    assert main(["encode", "--input", str(csv), "--out", str(out), "--t0", "0.004"]) == 0
    got = sorted({round(m.timestamp, 9) for m in read_log(out)})
    assert got == [0.0, 0.002, 0.004]
