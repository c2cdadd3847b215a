"""suspid encode -> CAN logs in every format -> Measurement; damaged logs; CLI errors."""
from __future__ import annotations

import numpy as np
import pytest

from estimator.decode import load_log_as_measurement
from tools.corrupt_log import corrupt_candump
import can

from suspid.can.logs import (FORMATS, LOG_FORMATS, ReadStats, is_can_log, log_format,
                              open_log_writer, read_log, read_log_arrays)
from suspid.cli import main
from suspid.errors import UsageError
from suspid.io.csvio import read_measurement
from suspid.models import get_model

from tests.can.conftest import Q2_STEP

#: timestamp resolution of each format as python-can writes it
T_TOL = {".log": 0.0, ".asc": 0.0, ".trc": 0.0, ".blf": 1e-9, ".mf4": 1e-6}


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf", ".trc", ".mf4"])
def test_encode_round_trip_every_format(q2_csv, tmp_path, suffix, capsys):
    out = tmp_path / f"q2{suffix}"
    assert main(["encode", "--input", str(q2_csv), "--out", str(out)]) == 0
    assert "frames" in capsys.readouterr().out
    ref = read_measurement(q2_csv, get_model("quarter2"))
    meas, stats = load_log_as_measurement(out, "quarter2")
    n = ref.t.size
    # per sample: SN_Sync, QC_Body, QC_Wheel, QC_Road; SN_Status at 10 Hz
    assert stats["accepted"] == 4 * n + len(range(0, n, 50))
    assert sum(stats["rejected"].values()) == 0 and stats["lost"] == 0
    assert meas.t.size == n
    np.testing.assert_allclose(meas.t, ref.t, rtol=0, atol=T_TOL[suffix] + 1e-12)
    if T_TOL[suffix] == 0.0:
        np.testing.assert_array_equal(meas.t, ref.t)  # the CSV's grid, bit for bit
    for ch, step in Q2_STEP.items():
        got = meas.measured.get(ch, meas.road.get(ch))
        want = ref.measured.get(ch, ref.road.get(ch))
        assert np.max(np.abs(got - want)) <= step / 2 * (1 + 1e-6), ch
    assert meas.warnings == [] or suffix == ".mf4"


def test_t0_shifts_times_and_model_inference(q2_csv, tmp_path):
    out = tmp_path / "shift.asc"
    assert main(["encode", "--input", str(q2_csv), "--out", str(out), "--t0", "1234.5678"]) == 0
    meas, _ = load_log_as_measurement(out, "quarter2", time_source="timestamp")
    ref = read_measurement(q2_csv, get_model("quarter2"))
    np.testing.assert_allclose(meas.t, ref.t + 1234.5678, atol=2e-9)
    # by default the data time is the sensor's clock (SN_Sync tick), whatever the log's origin
    tick, stats = load_log_as_measurement(out, "quarter2")
    assert stats["time_base"] == "tick"
    np.testing.assert_array_equal(tick.t, ref.t)


def test_a_gap_in_the_csv_is_a_gap_on_the_sensor_clock(q2_csv, tmp_path):
    """Rows missing from the CSV: the node's tick counts through them (frames lost), so the
    log read back on the sensor clock has the gap where the CSV has it, not closed up."""
    lines = q2_csv.read_text().splitlines()
    gap = tmp_path / "gap.csv"
    gap.write_text("\n".join(lines[:101] + lines[201:]) + "\n")    # samples 100..199 gone
    out = tmp_path / "gap.log"
    assert main(["encode", "--input", str(gap), "--out", str(out)]) == 0
    ref = read_measurement(gap, get_model("quarter2"))
    meas, stats = load_log_as_measurement(out, "quarter2")
    assert stats["time_base"] == "tick"
    ok = np.isfinite(meas.measured["x1"])
    np.testing.assert_allclose(meas.t[ok], ref.t, rtol=0, atol=1e-12)
    assert int(np.sum(~ok)) == 100        # the gap's cells, empty


def test_missing_channels_stay_missing(tmp_path):
    csv = tmp_path / "q1.csv"
    csv.write_text("t,x,y\n0,0.01,0\n0.002,0.02,0.001\n0.004,,0.002\n0.006,0.04,0.003\n")
    out = tmp_path / "q1.log"
    assert main(["encode", "--input", str(csv), "--out", str(out)]) == 0
    meas, stats = load_log_as_measurement(out, "quarter1")
    assert set(meas.measured) == {"x"} and set(meas.road) == {"y"}
    assert np.isnan(meas.measured["x"][2]) and meas.measured["x"][3] == pytest.approx(0.04)
    # x_dot, x_ddot, y_dot were never sent: absent, as in the CSV, no warning; the empty
    # cell is a one-sample gap of x
    assert len(meas.warnings) == 1 and "channel x: 1 of 4 samples missing" in meas.warnings[0]


def test_damaged_log_counts_every_bad_frame(q2_log, tmp_path):
    """Truncated lines, corrupted payloads, foreign IDs: all counted, data otherwise unchanged."""
    clean, clean_stats = load_log_as_measurement(q2_log, "quarter2")
    bad = tmp_path / "bad.log"
    n = corrupt_candump(q2_log, bad, truncated=15, corrupted=20, foreign=25, seed=3)
    meas, stats = load_log_as_measurement(bad, "quarter2")
    rej = stats["rejected"]
    assert rej["malformed"] + rej["dlc"] == n["truncated"] == 15
    assert rej["crc"] == n["corrupted"] == 20
    assert rej["unknown_id"] == n["foreign"] == 25
    assert sum(rej.values()) == 60
    assert stats["accepted"] == clean_stats["accepted"] - 35
    np.testing.assert_array_equal(meas.t, clean.t)
    for ch, v in meas.measured.items():
        ok = ~np.isnan(v)
        assert ok.sum() >= v.size - 35
        np.testing.assert_array_equal(v[ok], clean.measured[ch][ok])


def test_cli_identify_reports_frames_on_damaged_log(q2_log, tmp_path, capsys):
    import json

    bad = tmp_path / "bad.log"
    corrupt_candump(q2_log, bad, truncated=5, corrupted=5, foreign=5, seed=1)
    rc = main(["identify", "--model", "quarter2", "--input", str(bad), "--fix", "m1=300",
               "--init", "c1=1400", "--init", "k1=19000", "--init", "m2=38", "--init", "c2=280",
               "--init", "k2=190000", "--json"])
    out = json.loads(capsys.readouterr().out.splitlines()[0])
    assert rc == 0
    assert out["frames"]["accepted"] > 0 and sum(out["frames"]["rejected"].values()) == 15
    truth = get_model("quarter2").defaults()
    for name in ("c1", "k1", "m2"):
        assert out["params"][name] == pytest.approx(truth[name], rel=0.03), name


def test_reader_counts_malformed_lines_and_keeps_going(tmp_path):
    p = tmp_path / "x.log"
    p.write_text("(0.0) can0 110#00\n(0.1 can0\nnot a line at all\n(0.2) can0 11G#00\n"
                 "(0.3) can0 123#ABC\n(0.4) can0 123#A1B2 R\n")
    st = ReadStats()
    msgs = list(read_log(p, st))
    assert [m.timestamp for m in msgs] == [0.0, 0.4]
    assert st.malformed == 4 and st.examples[0].startswith(f"{p}:2")


def test_asc_reader_resumes_after_a_bad_line(q2_log, tmp_path):
    from suspid.can.logs import open_log_writer

    asc = tmp_path / "x.asc"
    with open_log_writer(asc) as w:
        for m in list(read_log(q2_log))[:40]:
            w.on_message_received(m)
    lines = asc.read_text().splitlines()
    i = [k for k, line in enumerate(lines) if " d 8 " in line][8]
    lines[i] = lines[i].replace(" d 8 ", " d 8 ZZ ")  # a non-hex byte
    asc.write_text("\n".join(lines) + "\n")
    st = ReadStats()
    assert len(list(read_log(asc, st))) == 39 and st.malformed == 1


def test_format_registry():
    assert log_format("a/B.MF4") == ".mf4" and is_can_log("x.BLF") and not is_can_log("x.csv")
    with pytest.raises(UsageError, match=r"\.log \(candump -L\)"):
        log_format("x.pcap")


def test_registry_is_the_one_suffix_table():
    assert list(LOG_FORMATS) == [".log", ".asc", ".blf", ".trc", ".mf4"]
    assert FORMATS == {s: f.name for s, f in LOG_FORMATS.items()}
    assert all(is_can_log(f"dir/X{s.upper()}") for s in LOG_FORMATS)
    with pytest.raises(UsageError) as err:
        log_format("x.pcap", "--log")
    msg = str(err.value)
    assert "\n" not in msg and "'.pcap'" in msg and "--log" in msg
    assert all(f"{s} ({f.name})" in msg for s, f in LOG_FORMATS.items())


@pytest.mark.parametrize("suffix", list(LOG_FORMATS))
def test_registry_writer_and_readers_round_trip(tmp_path, suffix):
    path = tmp_path / f"f{suffix}"
    sent = [can.Message(timestamp=100.0 + 0.01 * k, arbitration_id=0x100 + k,
                        data=bytes([k, 0xA5, k ^ 0xFF]), is_extended_id=False) for k in range(5)]
    with open_log_writer(path) as w:
        for m in sent:
            w.on_message_received(m)
    st = ReadStats()
    got = list(read_log(path, st))
    assert st.frames == 5 and st.malformed == 0
    assert [m.arbitration_id for m in got] == [m.arbitration_id for m in sent]
    assert [bytes(m.data) for m in got] == [bytes(m.data) for m in sent]
    fa = list(read_log_arrays(path))
    assert sum(len(b) for b in fa) == 5
    assert np.concatenate([b.arbitration_id for b in fa]).tolist() == [0x100 + k for k in range(5)]


def test_trc_reader_resumes_after_a_bad_line(tmp_path):
    path = tmp_path / "f.trc"
    with open_log_writer(path) as w:
        for k in range(6):
            w.on_message_received(can.Message(timestamp=1.0 + 0.01 * k, arbitration_id=0x200,
                                              data=bytes([k] * 8), is_extended_id=False))
    lines = path.read_text().splitlines()
    i = [k for k, line in enumerate(lines) if not line.startswith(";") and line.strip()][2]
    lines[i] = lines[i].replace(lines[i].split()[-1], "ZZ")   # a non-hex last byte
    path.write_text("\n".join(lines) + "\n")
    st = ReadStats()
    got = list(read_log(path, st))
    assert len(got) == 5 and st.malformed == 1 and st.examples[0].startswith(f"{path}:{i + 1}")


@pytest.mark.parametrize("args, fragment", [
    (["--dbc", "missing.dbc"], "missing.dbc: no such DBC file"),
    (["--out", "x.pcap"], "unknown output log format '.pcap'"),
])
def test_encode_errors_exit_2_one_line(q2_csv, tmp_path, capsys, args, fragment):
    argv = ["encode", "--input", str(q2_csv), "--out", str(tmp_path / "o.log")] + args
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and fragment in err and err.count("\n") == 1
    assert "Traceback" not in err


def test_garbage_csv_exit_2(tmp_path, capsys):
    bad = tmp_path / "g.csv"
    bad.write_text("t,x1\n0,abc\n")
    assert main(["encode", "--input", str(bad), "--out", str(tmp_path / "o.log")]) == 2
    err = capsys.readouterr().err
    assert "g.csv:2" in err and "'x1'" in err and err.count("\n") == 1


def test_log_without_model_frames_is_input_error(tmp_path):
    from suspid.errors import InputError

    p = tmp_path / "foreign.log"
    p.write_text("(0.0) can0 7DF#0102030405060708\n(0.1) can0 7DF#0102030405060708\n")
    with pytest.raises(InputError, match="no accepted frame"):
        load_log_as_measurement(p, "quarter2")


def test_a_skipped_line_is_named_once(q2_log, tmp_path):
    """A comment line atop a candump log is skipped with a warning naming file and line
    once (was: "F: skipped F:1: ...")."""
    log = tmp_path / "commented.log"
    log.write_text("# recorded with candump -L\n" + q2_log.read_text())
    meas, stats = load_log_as_measurement(log, "quarter2")
    assert stats["rejected"]["malformed"] == 1
    assert f"{log}:1: expected '(seconds)' first, got '#' (skipped)" in meas.warnings
    assert not any(w.count(str(log)) > 1 for w in meas.warnings)
