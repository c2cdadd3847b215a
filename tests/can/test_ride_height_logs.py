"""Ride heights on the bus: a CSV's ride heights encoded into their DBC messages and read
back by the decoder (what ``suspid identify --input LOG`` reads), within quantization."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from estimator.identify.inputs import read_input
from suspid.can.dbc import channel_signals
from suspid.cli import main
from suspid.excitation import make_scenario
from suspid.io.csvio import read_measurement, write_measurement
from suspid.models import MODELS, get_model
from suspid.simulate import simulate


def _steps(db, model_name: str) -> dict[str, float]:
    return {ch: db.get_message_by_name(msg).get_signal_by_name(sig).scale
            for ch, msg, sig in channel_signals(db, model_name)}


@pytest.mark.parametrize("suffix", [".log", ".blf"])
@pytest.mark.parametrize("model_name", list(MODELS))
def test_encoded_ride_heights_read_back_within_quantization(db, tmp_path: Path, model_name: str,
                                                            suffix: str, capsys) -> None:
    m = get_model(model_name)
    p = m.defaults()
    t, road, x0 = make_scenario(m, "bump", duration=1.5, fs=500.0, params=p, t0=0.2)
    out = simulate(m, p, t, road, x0)
    chans = list(m.channel_set("production")) + [f"{d}_dot" for d in m.ride_heights]
    cols = {c: out[c].copy() for c in chans}
    cols[m.ride_heights[0]][100:110] = np.nan   # missing samples stay missing
    csv_path = tmp_path / "prod.csv"
    write_measurement(csv_path, t, cols)
    log = tmp_path / f"prod{suffix}"
    assert main(["encode", "--input", str(csv_path), "--out", str(log)]) == 0
    said = capsys.readouterr().out
    rh_msgs = {msg for ch, msg, _ in channel_signals(db, model_name) if ch in m.ride_heights}
    assert all(f" {msg}" in said for msg in rh_msgs) and f"model {model_name}" in said
    ref = read_measurement(csv_path, m)
    meas, frames = read_input(log, m)
    assert frames is not None and sum(frames["rejected"].values()) == 0
    assert set(meas.measured) == set(chans) and meas.road == {}
    np.testing.assert_allclose(meas.t, ref.t, atol=1e-9)
    steps = _steps(db, model_name)
    for c in chans:
        a, b = meas.measured[c], ref.measured[c]
        assert np.array_equal(np.isnan(a), np.isnan(b)), c
        ok = ~np.isnan(b)
        assert np.max(np.abs(a[ok] - b[ok])) <= steps[c] / 2 * (1 + 1e-6), c
        if c in m.ride_height_channels:   # the struts move (the bump is symmetric: no roll)
            assert np.ptp(b[ok]) > 50 * steps[c], c
    assert np.isnan(meas.measured[m.ride_heights[0]][100:110]).all()


def test_identify_on_an_encoded_production_log(tmp_path: Path, capsys) -> None:
    """identify --input LOG compares the decoded ride heights (quarter2, road on the bus)."""
    m = get_model("quarter2")
    p = m.defaults()
    t, road, x0 = make_scenario(m, "iso8608", duration=4.0, fs=200.0, params=p, seed=2)
    out = simulate(m, p, t, road, x0)
    csv_path = tmp_path / "q2.csv"
    write_measurement(csv_path, t, {c: out[c] for c in ("r", "r_dot", "x1_ddot", "d")})
    log = tmp_path / "q2.log"
    assert main(["encode", "--input", str(csv_path), "--out", str(log)]) == 0
    capsys.readouterr()
    assert main(["identify", "--model", "quarter2", "--input", str(log), "--fix",
                 f"m1={p['m1']}", "--fix", f"m2={p['m2']}", "--cost", "frobenius", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["success"] and "d" in res["rms_residual"]
    assert res["rms_residual"]["d"] < 1e-5   # within the 10 um quantization
    for k in ("c1", "k1", "c2", "k2"):
        assert res["params"][k] == pytest.approx(p[k], rel=0.02), k
