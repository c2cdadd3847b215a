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


def test_loads_strict_with_expected_messages(db):
    names = {m.name for m in db.messages}
    assert SENSOR_MESSAGES | {"SN_Sync", "SN_Status", "SUSPID_Alert"} <= names
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
    expected = list(m.channels) + list(m.roads) + [f"{r}_dot" for r in m.roads]
    assert sorted(mapped) == sorted(expected)


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
