"""Logs of several CAN buses: the channel python-can's readers give, ``can.channel`` of a
``--config`` file.

A logger with two CAN ports writes both buses into one file. With a DBC that has no CRC or
counter (a user's own, through ``--map``) the frames of an identifier sent on both buses
used to be decoded as one stream. Here channel 1 carries the sensor's values (the CSV)
and channel 2 the same identifier with other values, in every log format.
"""
from __future__ import annotations

import json
import struct
from pathlib import Path

import can
import numpy as np
import pytest

from estimator.decode.log_input import load_log_as_measurement
from estimator.fleet.drive import IdentifySettings, load_drive
from suspid.can.signal_map import SignalMap
from suspid.can.logs import (ReadStats, channel_label, channel_wanted, open_log_writer,
                             read_log, read_log_arrays)
from suspid.cli import main
from suspid.errors import UsageError
from suspid.io.csvio import read_measurement
from suspid.models import get_model
from tests.conftest import write_config

#: a logger's own DBC: no CRC, no counter, heights in m
HEIGHT_DBC = '''VERSION ""
BS_:
BU_: Logger
BO_ 291 Height: 6 Logger
 SG_ Body : 0|16@1- (0.00001,0) [-0.3|0.3] "m" Logger
 SG_ Wheel : 16|16@1- (0.00001,0) [-0.3|0.3] "m" Logger
 SG_ Road : 32|16@1- (0.00001,0) [-0.3|0.3] "m" Logger
'''
MAP = ["x1=Height.Body", "x2=Height.Wheel", "r=Height.Road"]
STEP = 1e-5
T0 = 1.7e9

#: format -> (Message.channel written for the sensor's bus, for the other bus, the option
#: value naming the sensor's bus as the file shows it)
FORMATS = {".asc": (0, 1, "1"), ".blf": (0, 1, "1"), ".trc": (0, 1, "1"),
           ".mf4": (1, 2, "1"), ".log": ("can1", "can0", "can1")}


@pytest.fixture(scope="module")
def height_dbc(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("dbc") / "height.dbc"
    p.write_text(HEIGHT_DBC)
    return p


def _frame(v1: float, v2: float, r: float, ts: float, channel: object) -> can.Message:
    data = struct.pack("<hhh", *(int(round(v / STEP)) for v in (v1, v2, r)))
    return can.Message(timestamp=ts, arbitration_id=0x123, is_extended_id=False, data=data,
                       channel=channel)


def _two_bus_log(csv: Path, out: Path, sensor: object, other: object) -> int:
    """The CSV's x1/x2/r on the sensor's bus, reversed and scaled ones 50 µs later on the
    other; returns the frames per bus."""
    meas = read_measurement(csv, get_model("quarter2"))
    x1, x2, r = meas.measured["x1"], meas.measured["x2"], meas.road["r"]
    with open_log_writer(out) as w:
        for i, t in enumerate(meas.t):
            w.on_message_received(_frame(x1[i], x2[i], r[i], T0 + t, sensor))
            w.on_message_received(_frame(-x1[-1 - i], 0.5 * x2[-1 - i], 0.5 * r[-1 - i],
                                         T0 + t + 5e-5, other))
    return int(meas.t.size)


@pytest.fixture(scope="module", params=list(FORMATS))
def two_bus(request, q2_csv, tmp_path_factory) -> tuple[Path, str, int]:
    suf = request.param
    sensor, other, option = FORMATS[suf]
    out = tmp_path_factory.mktemp("twobus") / f"two{suf}"
    n = _two_bus_log(q2_csv, out, sensor, other)
    return out, option, n


def test_readers_channel_per_format(tmp_path):
    """What python-can's writers put in the file, what its readers give as
    ``Message.channel``, and the label suspid names it by (the file's own)."""
    got = {}
    for suf, (a, b, _) in FORMATS.items():
        p = tmp_path / f"ch{suf}"
        with open_log_writer(p) as w:
            for k, ch in enumerate((a, b)):
                w.on_message_received(_frame(0.0, 0.0, 0.0, T0 + k, ch))
        got[suf] = [(m.channel, channel_label(suf, m.channel)) for m in can.LogReader(str(p))]
    # ASC/BLF: the file counts from 1, python-can from 0; TRC/MDF4: as the file has it
    assert got[".asc"] == [(0, "1"), (1, "2")]
    assert got[".blf"] == [(0, "1"), (1, "2")]
    assert got[".trc"] == [(1, "1"), (2, "2")]     # TRCWriter wrote channel + 1
    assert got[".mf4"] == [(1, "1"), (2, "2")]
    assert got[".log"] == [("can1", "can1"), ("can0", "can0")]
    asc = (tmp_path / "ch.asc").read_text().splitlines()
    assert [ln.split()[1] for ln in asc if ln.strip().endswith("00 00 00 00 00 00")] == ["1", "2"]
    trc = (tmp_path / "ch.trc").read_text().splitlines()
    assert [ln.split()[3] for ln in trc if " DT " in ln] == ["1", "2"]


@pytest.mark.parametrize("text, suf, label", [
    ("1", ".asc", "1"), ("CAN1", ".mf4", "1"), ("ch2", ".blf", "2"), ("channel 2", ".trc", "2"),
    ("01", ".asc", "1"), ("can1", ".log", "can1"), ("1", ".log", "1"), ("vcan0", ".log", "vcan0")])
def test_option_values(text, suf, label):
    assert channel_wanted(suf, text) == label


def test_one_channel_equals_the_csv(two_bus, q2_csv, height_dbc):
    path, option, n = two_bus
    meas, frames = load_log_as_measurement(path, "quarter2", height_dbc, MAP, channel=option)
    csv = read_measurement(q2_csv, get_model("quarter2"))
    for ch in ("x1", "x2"):
        assert meas.measured[ch].shape == csv.measured[ch].shape
        assert np.max(np.abs(meas.measured[ch] - csv.measured[ch])) <= STEP / 2 + 1e-12
    assert np.max(np.abs(meas.road["r"] - csv.road["r"])) <= STEP / 2 + 1e-12
    np.testing.assert_allclose(meas.t - meas.t[0], csv.t - csv.t[0], atol=1e-6)
    assert frames["accepted"] == n
    assert frames["channel"] == option
    assert frames["other_channel"] == n
    assert sorted(frames["channels"].values()) == [n, n]
    assert not any("bus channels" in w for w in meas.warnings)


def test_without_the_option_a_warning_names_the_channels(two_bus, height_dbc):
    path, option, n = two_bus
    meas, frames = load_log_as_measurement(path, "quarter2", height_dbc, MAP)
    warned = [w for w in meas.warnings if "bus channels" in w]
    other = "can0" if option == "can1" else "2"
    assert len(warned) == 1
    assert f"{option} ({n} frames)" in warned[0] and f"{other} ({n} frames)" in warned[0]
    assert "can.channel" in warned[0]
    assert frames["accepted"] == 2 * n          # both streams decoded: what the warning says
    assert "other_channel" not in frames


def test_an_absent_channel_is_an_error_listing_the_present_ones(two_bus):
    path, option, n = two_bus
    with pytest.raises(UsageError) as exc:
        list(read_log_arrays(path, ReadStats(), channel="7"))
    msg = str(exc.value)
    assert "can.channel 7" in msg and f"{option} ({n} frames)" in msg and str(path) in msg
    with pytest.raises(UsageError):
        list(read_log(path, ReadStats(), channel="7"))


def test_message_reader_selects_too(two_bus):
    path, option, n = two_bus
    st = ReadStats()
    msgs = list(read_log(path, st, channel=option))
    assert len(msgs) == n and st.other_channel == n
    assert {channel_label(path.suffix, m.channel) for m in msgs} == {option}


def _channel(tmp_path, channel: str) -> list[str]:
    """``--config`` with ``[can] channel`` (and no data-driven start: a short fit)."""
    return ["--config", write_config(tmp_path, f'[can]\nchannel = "{channel}"\n'
                                               "[fit]\ndata_start = false\n")]


def test_identify_cli(two_bus, height_dbc, capsys, tmp_path):
    path, option, n = two_bus
    args = ["identify", "--model", "quarter2", "--input", str(path), "--dbc", str(height_dbc),
            "--map", MAP[0], "--map", MAP[1], "--map", MAP[2], "--fix", "m1=300", "--fix", "m2=40",
            "--maxfev", "10", "--json"]
    assert main(args + _channel(tmp_path, option)) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["frames"]["other_channel"] == n and out["frames"]["accepted"] == n
    assert not any("bus channels" in w for w in out["warnings"])
    assert main(args + _channel(tmp_path, "9")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "channels present" in err[0]


def test_fleet_reads_one_channel(two_bus, height_dbc):
    path, option, n = two_bus
    settings = IdentifySettings(model="quarter2", dbc=str(height_dbc),
                                signal_map=SignalMap.from_strings(MAP), can_channel=option)
    _, frames = load_drive(path, get_model("quarter2"), settings)
    assert frames is not None and frames["other_channel"] == n
    assert '"can_channel"' in settings.key()
    plain = IdentifySettings(model="quarter2", dbc=str(height_dbc))
    assert "can_channel" not in plain.key()     # the key of logs read whole is unchanged


def test_monitor_cli(two_bus, height_dbc, capsys, tmp_path):
    path, option, n = two_bus
    args = ["monitor", "--model", "quarter2", "--input", str(path), "--dbc", str(height_dbc),
            "--map", MAP[0], "--map", MAP[1], "--map", MAP[2], "--fix", "m1=300",
            "--fix", "m2=40", "--window", "1", "--step", "0.5", "--jsonl"]
    assert main(args + ["--config", write_config(tmp_path, f'[can]\nchannel = "{option}"\n')]) == 0
    cap = capsys.readouterr()
    summary = [json.loads(ln) for ln in cap.out.splitlines()][-1]
    assert summary["frames"]["other_channel"] == n and summary["frames"]["accepted"] == n
    assert "bus channels" not in cap.err
    assert main(args) == 0
    cap = capsys.readouterr()
    assert "the sensor's messages are on 2 bus channels" in cap.err
    summary = [json.loads(ln) for ln in cap.out.splitlines()][-1]
    assert summary["frames"]["accepted"] == 2 * n


def test_a_csv_has_no_bus_channel_the_option_is_warned(q2_csv, capsys, tmp_path):
    args = ["identify", "--model", "quarter2", "--input", str(q2_csv), "--fix", "m1=300",
            "--fix", "m2=40", "--maxfev", "10", "--json"]
    assert main(args + _channel(tmp_path, "2")) == 0
    warns = json.loads(capsys.readouterr().out)["warnings"]
    assert any("can.channel 2 not used" in w and str(q2_csv) in w for w in warns), warns
    assert main(args) == 0
    assert not any("can.channel" in w for w in json.loads(capsys.readouterr().out)["warnings"])
