"""Real recordings (../shared/realdata): CANedge MF4 + CANmod.gps DBC, candump drive log."""
from __future__ import annotations

import numpy as np

from estimator.decode import load_log_as_measurement
from suspid.cli import main


def test_canedge_mf4_vertical_acceleration_minus_gravity(realdata, tmp_path):
    d = realdata / "canedge-imu"
    mf4 = d / "00000002-60FE415D.MF4"
    meas, stats = load_log_as_measurement(mf4, "quarter2", d / "canmod-gps.dbc",
                                          ["x1_ddot=gnss_imu.AccelerationX-9.81"])
    # 60,750 gnss_imu frames accepted; the other CANmod messages (IDs 1-8, 571 frames each)
    # are in the DBC but unmapped; IDs the DBC does not know (0x7E8 and an extended ID from
    # other devices on the logger: 7,267 + 1,200 frames) are counted as foreign
    assert stats["accepted"] == 60750
    assert stats["ignored"] == 8 * 571
    assert stats["rejected"]["unknown_id"] == 7267 + 1200
    assert sum(v for k, v in stats["rejected"].items() if k != "unknown_id") == 0
    x = meas.measured["x1_ddot"]
    assert set(meas.measured) == {"x1_ddot"} and meas.road == {}
    dt = np.diff(meas.t)
    assert np.allclose(dt, 0.01, rtol=1e-3)                   # a uniform 100 Hz grid
    assert 595 < meas.t[-1] - meas.t[0] < 601                 # the 10-minute drive
    assert np.isnan(x).mean() < 0.02                          # gaps marked, few
    assert abs(np.nanmean(x)) < 0.3                           # gravity removed (mean 9.6)
    assert 0.05 < np.nanstd(x) < 3.0                          # road-induced vibration
    assert x[~np.isnan(x)].min() >= -64 - 9.81                # within the sensor's range
    # resolution 0.125 m/s^2: every value sits on the DBC's grid shifted by 9.81
    q = (x[~np.isnan(x)] + 9.81 + 64) / 0.125
    assert np.allclose(q, np.round(q), atol=1e-6)


def test_map_file_with_dbc_and_mean_removal(realdata, tmp_path):
    d = realdata / "candump-drive"
    cfg = tmp_path / "drive.toml"
    cfg.write_text(f'dbc = "{(d / "sample_can_spec.dbc").as_posix()}"\n'
                   '[map]\nx_ddot = "ID_D0.ACCEL_LAT - mean"\n')
    meas, stats = load_log_as_measurement(d / "can_sample.log", "quarter1", signal_map=cfg)
    assert stats["accepted"] == 4514
    assert abs(np.nanmean(meas.measured["x_ddot"])) < 1e-9


def test_candump_drive_with_unrelated_traffic(realdata):
    d = realdata / "candump-drive"
    meas, stats = load_log_as_measurement(d / "can_sample.log", "quarter1",
                                          d / "sample_can_spec.dbc", ["x_ddot=ID_D0.ACCEL_LONG"])
    # 82,558 frames, 35 IDs: ID_D0 (0x0D0) carries the mapped signal; the DBC's other
    # messages are ignored; the 26 IDs the DBC does not define are rejected, not fatal
    assert stats["accepted"] == 4514
    assert stats["accepted"] + stats["ignored"] + stats["rejected"]["unknown_id"] == 82558
    assert stats["rejected"]["unknown_id"] > 40000
    assert meas.t.size == 4514 and np.allclose(np.diff(meas.t), 0.02, rtol=1e-3)
    x = meas.measured["x_ddot"]
    assert not np.isnan(x).any() and np.abs(x).max() < 19.05


def test_identify_cli_on_foreign_log_needs_a_map(realdata, capsys):
    d = realdata / "candump-drive"
    rc = main(["identify", "--model", "quarter1", "--input", str(d / "can_sample.log"),
               "--dbc", str(d / "sample_can_spec.dbc"), "--json"])
    assert rc == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "signal map" in err and err.count("\n") == 1
