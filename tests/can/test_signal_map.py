"""Signal-map syntax, config files and validation against a DBC and a model."""
from __future__ import annotations

import json
import struct

import pytest

from estimator.decode.listener import model_channels
from suspid.can.dbc import load_dbc
from suspid.can.signal_map import SignalMap, SignalMapping, merge_maps, parse_mapping
from suspid.cli import main
from suspid.errors import InputError, UsageError
from suspid.models import get_model
from tests.conftest import write_config


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
    merged = merge_maps([sm, SignalMap.from_strings(["x1_ddot=gnss_imu.AccelerationZ"])])
    assert merged is not None
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


MM_DBC = '''VERSION ""
BS_:
BU_: Logger
BO_ 291 Height: 8 Logger
 SG_ Body : 0|16@1- (0.01,0) [-300|300] "mm" Logger
 SG_ Wheel : 16|16@1- (0.00001,0) [-0.3|0.3] "m" Logger
 SG_ BodyAcc : 32|16@1- (0.001,0) [-30|30] "g" Logger
 SG_ Pitch : 48|16@1- (0.01,0) [-300|300] "deg" Logger
'''


def test_a_signal_in_another_unit_without_a_scale_is_warned(tmp_path):
    """A logger's DBC gives heights in mm or accelerations in g; mapped without a factor the
    fit silently mixes units (a quarter car with the body in mm and the wheel in m:
    c2 ran to 1.9e12). Warned with the factor to give; a mapping with a scale is the user's."""
    dbc = tmp_path / "mm.dbc"
    dbc.write_text(MM_DBC)
    db = load_dbc(dbc)
    q2 = get_model("quarter2")
    sm = SignalMap.from_strings(["x1=Height.Body", "x2=Height.Wheel", "x1_ddot=Height.BodyAcc",
                                 "x2_ddot=Height.BodyAcc*9.81"])
    w = sm.unit_warnings(db, q2)
    assert w == ["--map: x1=Height.Body: signal Height.Body is in 'mm' by the DBC but x1 is read in m, "
                 "with no scale; give the factor to SI (e.g. x1=Height.Body*0.001)",
                 "--map: x1_ddot=Height.BodyAcc: signal Height.BodyAcc is in 'g' by the DBC but x1_ddot "
                 "is read in m/s^2, with no scale; give the factor to SI (e.g. x1_ddot=Height.BodyAcc*9.80665)"]
    h4 = SignalMap.from_strings(["delta=Height.Pitch"])
    assert h4.unit_warnings(db, get_model("half4")) == [
        "--map: delta=Height.Pitch: signal Height.Pitch is in 'deg' by the DBC but delta is read in rad, "
        "with no scale; give the factor to SI (e.g. delta=Height.Pitch*0.0174533)"]
    assert SignalMap.from_strings(["x1=Height.Body*0.001"]).unit_warnings(db, q2) == []


def test_the_unit_warning_reaches_identify(tmp_path, capsys):
    dbc = tmp_path / "mm.dbc"
    dbc.write_text(MM_DBC)
    log = tmp_path / "mm.log"
    log.write_text("".join(f"({1.7e9 + k / 200:.6f}) can0 123#"
                           f"{struct.pack('<hhhh', 100 * (k % 7), 10 * (k % 5), 0, 0).hex().upper()}\n"
                           for k in range(200)))
    rc = main(["identify", "--model", "quarter2", "--input", str(log), "--dbc", str(dbc), "--map",
               "x1=Height.Body", "--map", "x2=Height.Wheel", "--fix", "m1=300", "--fix", "m2=40",
               "--maxfev", "20", "--config", write_config(tmp_path, "[fit]\ndata_start = false\n"),
               "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert any("Height.Body is in 'mm'" in w for w in out["warnings"])


def test_a_speed_factor_is_offered_for_speeds_only(tmp_path):
    """A signal in km/h mapped onto an acceleration: the unit is named, no km/h -> m/s
    factor offered (was: 'e.g. x1_ddot=Speed.V*0.277778'); onto a velocity it is."""
    dbc = tmp_path / "kmh.dbc"
    dbc.write_text(MM_DBC.replace('"deg"', '"km/h"'))
    db = load_dbc(dbc)
    q2 = get_model("quarter2")
    (acc,) = SignalMap.from_strings(["x1_ddot=Height.Pitch"]).unit_warnings(db, q2)
    assert "is in 'km/h' by the DBC but x1_ddot is read in m/s^2" in acc
    assert acc.endswith("give the factor to SI") and "0.277778" not in acc
    (vel,) = SignalMap.from_strings(["x1_dot=Height.Pitch"]).unit_warnings(db, q2)
    assert vel.endswith("(e.g. x1_dot=Height.Pitch*0.277778)")
    # mm onto an acceleration is no length conversion either
    (mm,) = SignalMap.from_strings(["x1_ddot=Height.Body"]).unit_warnings(db, q2)
    assert mm.endswith("give the factor to SI")
