"""Signal-map syntax, config files and validation against a DBC and a model."""
from __future__ import annotations

import json

import pytest

from estimator.decode.listener import model_channels
from suspid.can.signal_map import SignalMap, SignalMapping, parse_mapping
from suspid.errors import InputError, UsageError
from suspid.models import get_model


@pytest.mark.parametrize("text, expected", [
    ("x1_ddot=gnss_imu.AccelerationX-9.81", SignalMapping("x1_ddot", "gnss_imu", "AccelerationX", 1.0, -9.81)),
    ("x_ddot = -1 * gnss_imu.AccelerationX + 9.81", SignalMapping("x_ddot", "gnss_imu", "AccelerationX", -1.0, 9.81)),
    ("x_ddot=-gnss_imu.AccelerationX", SignalMapping("x_ddot", "gnss_imu", "AccelerationX", -1.0, 0.0)),
    ("x1_ddot=gnss_imu.AccelerationX-mean", SignalMapping("x1_ddot", "gnss_imu", "AccelerationX", 1.0, "mean")),
    ("x2=0x123.Height*0.001", SignalMapping("x2", "0x123", "Height", 0.001, 0.0)),
    ("x=2*A.B*3+(-1e-3)", SignalMapping("x", "A", "B", 6.0, -0.001)),
    # the signal-first form of the brief means the same
    ("gnss_imu.AccelerationX=x1_ddot*1+(-9.81)", SignalMapping("x1_ddot", "gnss_imu", "AccelerationX", 1.0, -9.81)),
])
def test_parse(text, expected):
    assert parse_mapping(text) == expected
    assert parse_mapping(str(expected)) == expected  # str() is parseable back


@pytest.mark.parametrize("text", ["x1_ddot", "x1_ddot=gnss_imu", "x=A.B-foo", "x=A.B+mean", "=A.B"])
def test_parse_errors_name_the_option_and_form(text):
    with pytest.raises(UsageError) as exc:
        parse_mapping(text, "--map")
    assert "--map" in str(exc.value)


def test_toml_and_json_files(tmp_path):
    toml = tmp_path / "m.toml"
    toml.write_text('dbc = "canmod-gps.dbc"\n[map]\nx1_ddot = "gnss_imu.AccelerationX - 9.81"\n'
                    'x1 = { message = "gnss_imu", signal = "AccelerationY", scale = 2.0, offset = "mean" }\n')
    sm = SignalMap.from_file(toml)
    assert sm.dbc == tmp_path / "canmod-gps.dbc"
    assert sm.mappings == [SignalMapping("x1_ddot", "gnss_imu", "AccelerationX", 1.0, -9.81),
                           SignalMapping("x1", "gnss_imu", "AccelerationY", 2.0, "mean")]
    js = tmp_path / "m.json"
    js.write_text(json.dumps({"map": {"x1_ddot": "gnss_imu.AccelerationX-9.81"}}))
    assert SignalMap.from_file(js).mappings[0].offset == -9.81
    merged = SignalMap.from_args(["x1_ddot=gnss_imu.AccelerationZ"], toml)
    assert [m.signal for m in merged.mappings] == ["AccelerationY", "AccelerationZ"]


@pytest.mark.parametrize("content, fragment", [
    ("[map]\n", "expected a 'map' table"),
    ("[map]\nx1 = 3\n", "expected a string or a table"),
    ("[map]\nx1 = { message = \"a\" }\n", "expected keys"),
    ("[map\n", "invalid TOML"),
])
def test_bad_files(tmp_path, content, fragment):
    p = tmp_path / "m.toml"
    p.write_text(content)
    with pytest.raises((InputError, UsageError)) as exc:
        SignalMap.from_file(p)
    assert fragment in str(exc.value) and str(p) in str(exc.value)


def test_validate_against_dbc_and_model(realdata):
    from suspid.can.dbc import load_dbc

    db = load_dbc(realdata / "canedge-imu" / "canmod-gps.dbc")
    allowed = model_channels(get_model("quarter2"))
    SignalMap.from_strings(["x1_ddot=gnss_imu.AccelerationX"]).validate(db, allowed)
    SignalMap.from_strings(["x1_ddot=9.AccelerationX"]).validate(db, allowed)  # by frame ID
    cases = [("x1_ddot=nomsg.AccelerationX", "message 'nomsg'"),
             ("x1_ddot=gnss_imu.NoSignal", "no signal 'NoSignal'"),
             ("x9=gnss_imu.AccelerationX", "channel 'x9'")]
    for text, fragment in cases:
        with pytest.raises((InputError, UsageError)) as exc:
            SignalMap.from_strings([text]).validate(db, allowed)
        assert fragment in str(exc.value)
