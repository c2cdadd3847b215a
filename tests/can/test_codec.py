"""Packing and unpacking: quantization round trip, saturation, fast decoder == cantools."""
from __future__ import annotations

import math

import pytest
from cantools.database.can import Database
from hypothesis import given, settings
from hypothesis import strategies as st

from suspid.can.codec import (MessageCodec, SensorEncoder, decode_alert, encode_alert,
                              signal_spec)
from suspid.can.crc import e2e_check
from suspid.can.dbc import channel_signals, load_dbc
from suspid.can.signal_map import SignalMap
from suspid.errors import UsageError
from suspid.models import MODELS, get_model

from estimator.decode.routes import compile_row as _compile_row


def _channel_specs(db, model_name):
    out = {}
    for ch, msg, sig in channel_signals(db, model_name):
        out[ch] = (db.get_message_by_name(msg), sig, signal_spec(db.get_message_by_name(msg), sig))
    return out


@pytest.mark.parametrize("model_name", list(MODELS))
def test_round_trip_within_half_a_step(db, model_name):
    specs = _channel_specs(db, model_name)
    m = get_model(model_name)
    # every contract channel: motions, ride heights (body accelerations among them), roads
    assert set(specs) == set(m.channels) | set(m.ride_height_channels) | set(m.input_names)
    enc = SensorEncoder(db, model_name, list(specs))

    @settings(max_examples=150, deadline=None)
    @given(st.data())
    def check(data):
        values = {}
        for ch, (_, _, spec) in specs.items():
            lo = spec.raw_min * spec.scale + spec.offset
            hi = spec.raw_max * spec.scale + spec.offset
            values[ch] = data.draw(st.floats(lo, hi, allow_nan=False), label=ch)
        tick = data.draw(st.integers(0, 2**32 - 1), label="tick")
        frames = dict(enc.sample_frames(tick, values))
        for ch, (msg, sig, spec) in specs.items():
            payload = frames[msg.frame_id]
            assert e2e_check(payload, msg.frame_id)
            assert payload[1] & 0x0F == tick % 15
            decoded = msg.decode(bytes(payload), decode_choices=False)
            assert decoded[f"{sig}Valid"] == 1
            assert abs(decoded[sig] - values[ch]) <= spec.scale / 2 * (1 + 1e-9), ch

    check()


def test_out_of_range_and_nan_are_sent_invalid(db):
    enc = SensorEncoder(db, "quarter2", ["x1", "x1_dot", "x1_ddot"])
    frames = dict(enc.sample_frames(3, {"x1": 0.5, "x1_dot": math.nan, "x1_ddot": 1.0}))
    msg = db.get_message_by_name("QC_Body")
    d = msg.decode(bytes(frames[msg.frame_id]))
    assert d["DispValid"] == 0 and d["Saturated"] == 1
    assert d["Disp"] == pytest.approx(0.32767)  # clamped to the top of the range
    assert d["VelValid"] == 0
    assert d["AccValid"] == 1 and d["Acc"] == pytest.approx(1.0)
    assert enc.saturated == {"x1": 1}
    # the decoder turns invalid signals into NaN
    maps = [m for m in SignalMap.from_dbc(db, "quarter2").mappings if m.message == "QC_Body"]
    row = _compile_row(msg, maps)(frames[msg.frame_id])
    assert math.isnan(row[0]) and math.isnan(row[1]) and row[2] == pytest.approx(1.0)


_EXTRA_DBC = '''VERSION ""
BS_:
BU_: A
BO_ 1280 Mixed: 8 A
 SG_ BigU12 : 7|12@0+ (0.5,-10) [-10|2037.5] "m" A
 SG_ BigS9 : 11|9@0- (0.01,0) [-2.56|2.55] "m" A
 SG_ LitS7 : 25|7@1- (2,1) [-127|127] "m" A
 SG_ Flt : 32|32@1- (1,0) [-1e9|1e9] "m" A
BO_ 1281 Wide: 8 A
 SG_ U64 : 0|64@1+ (1,0) [0|1.8446744073709552e19] "" A
SIG_VALTYPE_ 1280 Flt : 1;
'''


def _all_dbcs(realdata_path):
    dbs = [load_dbc()]
    extra = Database(strict=True)
    extra.add_dbc_string(_EXTRA_DBC)
    dbs.append(extra)
    if realdata_path is not None:
        dbs.append(load_dbc(realdata_path / "canedge-imu" / "canmod-gps.dbc"))
        dbs.append(load_dbc(realdata_path / "candump-drive" / "sample_can_spec.dbc"))
    return dbs


def test_fast_decoder_equals_cantools():
    from tests.can.conftest import REALDATA

    dbs = _all_dbcs(REALDATA if REALDATA.is_dir() else None)
    # (multiplexed messages -- the alert -- are decoded with cantools itself)
    messages = [(m, MessageCodec(m)) for db in dbs for m in db.messages if not m.is_multiplexed()]
    assert any(c.fast for _, c in messages) and any(not c.fast for _, c in messages)

    @settings(max_examples=200, deadline=None)
    @given(st.sampled_from(range(len(messages))), st.binary(min_size=64, max_size=64))
    def check(i, raw):
        msg, codec = messages[i]
        payload = raw[: msg.length]
        ref = msg.decode(payload, decode_choices=False, scaling=True, allow_truncated=False)
        got = dict(zip(codec.names, codec.decode(payload)))
        for name, val in got.items():
            exp = ref[name]
            if isinstance(exp, float) and math.isnan(exp):
                assert math.isnan(val)
            else:
                assert val == pytest.approx(exp, rel=1e-12, abs=1e-12), (msg.name, name)

    check()


def test_pack_raw_equals_cantools_encode(db):
    msg = db.get_message_by_name("HC_Pitch")
    codec = MessageCodec(msg, ["Disp", "Vel", "Acc", "DispValid", "Saturated"])
    data = codec.pack_raw((-1234, 32767, -32768, 1, 1))
    ref = msg.encode({"CRC": 0, "Counter": 0, "DispValid": 1, "VelValid": 0, "AccValid": 0,
                      "Saturated": 1, "Disp": -1234, "Vel": 32767, "Acc": -32768},
                     scaling=False)
    assert bytes(data) == ref


def test_alert_round_trip(db):
    msg = encode_alert(db, "quarter2", "c1", 987.6, 1500.0, "critical", counter=4)
    assert e2e_check(msg.data, msg.arbitration_id)
    out = decode_alert(db, msg.data)
    assert out["parameter"] == "c1" and out["model"] == "quarter2" and out["severity"] == "critical"
    assert out["value"] == pytest.approx(987.6, abs=0.05)
    assert out["nominal"] == pytest.approx(1500.0, abs=0.05)
    k = decode_alert(db, encode_alert(db, "half4", "k3", 201234.0, 200000.0).data)
    assert k["value"] == pytest.approx(201234.0, abs=1.0) and k["parameter"] == "k3"


@pytest.mark.parametrize("model_name", list(MODELS))
def test_alert_round_trip_for_every_parameter_of_every_model(db, model_name):
    m = get_model(model_name)
    for k, v in m.defaults().items():
        out = decode_alert(db, encode_alert(db, model_name, k, 0.6 * v, v).data)
        assert out["model"] == model_name and out["parameter"] == k
        assert out["value"] == pytest.approx(0.6 * v, rel=1e-3)


def test_alert_for_a_model_the_dbc_does_not_list_is_refused(db):
    m = get_model("full7")
    type(m).alert_id, old = 2, type(m).alert_id   # pretend full7 claimed half4's id
    try:
        with pytest.raises(UsageError, match="no SUSPID_Alert.Model id"):
            encode_alert(db, "full7", "c1", 1.0, 2.0)
    finally:
        type(m).alert_id = old


def test_encoder_refuses_channels_the_dbc_does_not_carry(db):
    from suspid.errors import UsageError

    with pytest.raises(UsageError, match="x9"):
        SensorEncoder(db, "quarter2", ["x1", "x9"])
    assert get_model("quarter2")
