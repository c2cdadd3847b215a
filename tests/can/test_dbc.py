"""suspension.dbc: strict loading, documentation, channel mapping, ranges; DBC errors."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from suspid.can.codec import signal_spec
from suspid.can.dbc import channel_signals, default_dbc_path, is_e2e, load_dbc
from suspid.errors import InputError
from suspid.excitation import make_scenario
from suspid.models import MODELS, get_model
from suspid.simulate import simulate

REPO = Path(__file__).resolve().parents[2]
SENSOR_MESSAGES = {"QC_Body", "QC_Wheel", "QC_Road", "HC_Body", "HC_Pitch", "HC_WheelFront",
                   "HC_WheelRear", "HC_RoadFront", "HC_RoadRear", "FC_Body", "FC_Pitch", "FC_Roll",
                   "FC_WheelFL", "FC_WheelFR", "FC_WheelRL", "FC_WheelRR", "FC_RoadFL", "FC_RoadFR",
                   "FC_RoadRL", "FC_RoadRR"}
RIDE_HEIGHT_MESSAGES = {"QC_RideHeight", "HC_RideHeightFront", "HC_RideHeightRear",
                        "FC_RideHeightFL", "FC_RideHeightFR", "FC_RideHeightRL", "FC_RideHeightRR"}
#: the CAN IDs of the sensor messages before the ride heights came: unchanged
EXISTING_IDS = {"QC_Body": 272, "QC_Wheel": 273, "QC_Road": 274, "HC_Body": 288, "HC_Pitch": 289,
                "HC_WheelFront": 290, "HC_WheelRear": 291, "HC_RoadFront": 292, "HC_RoadRear": 293,
                "FC_Body": 304, "FC_Pitch": 305, "FC_Roll": 306, "FC_WheelFL": 307,
                "FC_WheelFR": 308, "FC_WheelRL": 309, "FC_WheelRR": 310, "FC_RoadFL": 311,
                "FC_RoadFR": 312, "FC_RoadRL": 313, "FC_RoadRR": 314, "SN_Sync": 256,
                "SUSPID_Alert": 768, "SN_Status": 784}


def test_loads_strict_with_expected_messages(db):
    names = {m.name for m in db.messages}
    assert SENSOR_MESSAGES | RIDE_HEIGHT_MESSAGES | {"SN_Sync", "SN_Status", "SUSPID_Alert"} <= names
    assert {n: db.get_message_by_name(n).frame_id for n in EXISTING_IDS} == EXISTING_IDS
    assert db.get_message_by_name("SUSPID_Alert").is_multiplexed()


def test_one_dbc_source_the_repository_path_links_to_the_package_file():
    repo = REPO / "dbc" / "suspension.dbc"
    pkg = REPO / "suspid" / "data" / "suspension.dbc"
    assert repo.is_symlink() and not pkg.is_symlink()
    assert repo.resolve() == pkg.resolve()
    assert default_dbc_path().resolve() == pkg.resolve()


def test_alert_model_ids_and_sensor_sets_match_every_model(db):
    alert = db.get_message_by_name("SUSPID_Alert").get_signal_by_name("Model")
    sset = db.get_message_by_name("SN_Status").get_signal_by_name("SensorSet")
    for name in MODELS:
        m = get_model(name)
        assert str(alert.choices[m.alert_id]) == name
        assert m.sensor_set in sset.choices
    assert len({get_model(n).alert_id for n in MODELS}) == len(MODELS)


def test_every_parameter_has_an_alert_id(db):
    ids = {str(v) for v in db.get_message_by_name("SUSPID_Alert")
           .get_signal_by_name("ParamId").choices.values()}
    for name in MODELS:
        assert set(get_model(name).param_names) <= ids, name


def test_every_signal_has_comment_and_unit(db):
    for msg in db.messages:
        assert msg.comment, msg.name
        for sig in msg.signals:
            assert sig.comment and len(sig.comment) > 10, f"{msg.name}.{sig.name}"
            assert sig.unit, f"{msg.name}.{sig.name} has no unit"  # "-" when dimensionless
            if sig.scale != 1 or sig.name in ("SampleRate", "PeriodUs"):
                assert sig.unit != "-", f"{msg.name}.{sig.name} is physical"


def test_every_frame_is_e2e_protected_with_crc_and_counter(db):
    for msg in db.messages:
        assert is_e2e(msg), msg.name
        crc = msg.get_signal_by_name("CRC")
        cnt = msg.get_signal_by_name("Counter")
        assert (crc.start, crc.length, cnt.start, cnt.length) == (0, 8, 8, 4)
        assert cnt.maximum == 14


@pytest.mark.parametrize("model_name", list(MODELS))
def test_suspid_channel_attributes_cover_every_channel_once(db, model_name):
    m = get_model(model_name)
    mapped = [ch for ch, _, _ in channel_signals(db, model_name)]
    expected = (list(m.channels) + list(m.ride_height_channels) + list(m.roads)
                + [f"{r}_dot" for r in m.roads])
    assert sorted(mapped) == sorted(expected)


@pytest.mark.parametrize("model_name", list(MODELS))
def test_ride_heights_and_body_accelerations_have_signals(db, model_name):
    """Every ride height (with its rate) sits in a ride-height message of its own set, with
    E2E header and Valid bits, 10 um / +-0.25 m at least and +-5 m/s at least; every body
    coordinate's acceleration has a signal (the production set is all on the bus)."""
    m = get_model(model_name)
    sig = {ch: (msg, s) for ch, msg, s in channel_signals(db, model_name)}
    for d in m.ride_heights:
        msg_name, s = sig[d]
        assert msg_name in RIDE_HEIGHT_MESSAGES and sig[f"{d}_dot"][0] == msg_name
        msg = db.get_message_by_name(msg_name)
        assert is_e2e(msg) and {"DispValid", "VelValid", "Saturated"} <= {x.name for x in msg.signals}
        pos = signal_spec(msg, s)
        vel = signal_spec(msg, sig[f"{d}_dot"][1])
        assert pos.scale == 1e-05 and min(-pos.raw_min, pos.raw_max) * pos.scale >= 0.25
        assert vel.scale <= 5e-4 and min(-vel.raw_min, vel.raw_max) * vel.scale >= 5.0
        assert msg.get_signal_by_name(s).unit == "m"
        assert msg.get_signal_by_name(sig[f"{d}_dot"][1]).unit == "m/s"
    for c in m.channel_set("production"):
        assert c in sig, c
    # one message per strut, none shared with another channel of the model
    msgs = [sig[d][0] for d in m.ride_heights]
    assert len(set(msgs)) == len(msgs)
    others = {msg for ch, (msg, _) in sig.items() if ch not in m.ride_height_channels}
    assert not others & set(msgs)


@pytest.mark.parametrize("model_name", list(MODELS))
@pytest.mark.parametrize("scenario", ["initial", "curb", "bump", "iso8608"])
def test_ranges_cover_the_scenarios_with_margin(db, model_name, scenario):
    m = get_model(model_name)
    t, road, x0 = make_scenario(m, scenario, duration=3.0, fs=1000.0)
    out = simulate(m, m.defaults(), t, road, x0)
    for ch, msg_name, sig_name in channel_signals(db, model_name):
        spec = signal_spec(db.get_message_by_name(msg_name), sig_name)
        top = min(abs(spec.raw_min), spec.raw_max) * spec.scale
        peak = float(np.max(np.abs(out[ch])))
        assert peak < 0.98 * top, f"{ch} peaks at {peak:.4g}, {msg_name}.{sig_name} range {top:.4g}"


def test_missing_dbc_is_one_line_input_error(tmp_path):
    with pytest.raises(InputError) as exc:
        load_dbc(tmp_path / "nope.dbc")
    assert "nope.dbc" in str(exc.value) and "\n" not in str(exc.value)


def test_parse_error_names_the_line(tmp_path):
    bad = tmp_path / "bad.dbc"
    bad.write_text('VERSION ""\n\nBS_:\n\nBU_:\nBO_ 3 m: 8 Vector__XXX\n'
                   ' SG_ s : 0|6@1+ (1,0 [0|63] "m" Vector__XXX\n')
    with pytest.raises(InputError) as exc:
        load_dbc(bad)
    msg = str(exc.value)
    assert "bad.dbc" in msg and "line 7" in msg and "\n" not in msg


def test_foreign_real_dbcs_load(realdata):
    for p in ["canedge-imu/canmod-gps.dbc", "candump-drive/sample_can_spec.dbc"]:
        assert load_dbc(realdata / p).messages
