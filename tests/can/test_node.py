"""The simulated sensor node: scenarios, plant, noise, faults, pacing, the CLI."""
from __future__ import annotations

import json
import time

import can
import numpy as np
import pytest

from estimator.decode import DecodeListener, feed
from firmware_sim.faults import FaultConfig
from firmware_sim.node import NodeConfig, SensorNode
from firmware_sim.scenarios import SCENARIOS
from suspid.cli import main
from suspid.errors import UsageError
from suspid.can.dbc import channel_signals, load_dbc
from suspid.models import MODELS, get_model
from suspid.simulate import simulate

from tests.can.conftest import Q2_STEP


def _decode(node, **kw):
    lst = DecodeListener(node.model, node.db, **kw)
    feed(lst, node.frames())
    return lst


@pytest.mark.parametrize("scenario", SCENARIOS)
@pytest.mark.parametrize("model_name", list(MODELS))
def test_every_scenario_and_model_decodes_cleanly(scenario, model_name):
    node = SensorNode(NodeConfig(model=model_name, scenario=scenario, duration=1.0, rate=500))
    lst = _decode(node)
    st = lst.frame_stats()
    model = get_model(model_name)
    roads = set(model.input_names)
    # SN_Sync and the model's sensor messages (ride heights only when asked for); without a
    # road (initial) no road messages
    n_msgs = 1 + len({msg for ch, msg, _ in channel_signals(node.db, model_name)
                      if (scenario != "initial" or ch not in roads)
                      and ch not in model.ride_height_channels})
    assert n_msgs == {"quarter1": 3, "quarter2": 4, "half4": 7, "full7": 12}.get(model_name, n_msgs) \
        - len(model.roads) * (scenario == "initial")
    # 501 ticks of sensor frames; status at ticks 0, 50, ..., 500 and a final one
    assert st["accepted"] == 501 * n_msgs + 12
    assert sum(st["rejected"].values()) == 0
    assert lst.node_status["sample_rate"] == 500 and lst.node_status["state"] == 4  # stopping
    assert lst.node_status["sensor_set"] == model.sensor_set


def test_noise_free_node_equals_the_core_simulation():
    node = SensorNode(NodeConfig(scenario="bump", duration=2.0, rate=1000, noise=0.0))
    lst = _decode(node)
    al = lst.aligned()
    m = get_model("quarter2")
    ref = simulate(m, m.defaults(), node.setup.t, node.setup.road, node.setup.x0)
    np.testing.assert_allclose(al.t, node.setup.t, atol=1e-12)
    for ch, step in Q2_STEP.items():
        assert np.max(np.abs(al.values[ch] - ref[ch])) <= step / 2 * (1 + 1e-6), ch


def test_sensor_noise_has_the_configured_size():
    quiet = _decode(SensorNode(NodeConfig(scenario="random", duration=2.0, noise=0.0))).aligned()
    noisy = _decode(SensorNode(NodeConfig(scenario="random", duration=2.0, noise=5.0))).aligned()
    d = noisy.values["x1_ddot"] - quiet.values["x1_ddot"]
    assert np.std(d) == pytest.approx(5 * 0.02, rel=0.1)


def test_damper_wear_c1_drifts_down():
    node = SensorNode(NodeConfig(scenario="damper-wear", duration=40.0, rate=500,
                                 wear_start=10.0, wear_to=0.4))
    assert node.truth(5.0)["c1"] == 1500.0
    assert node.truth(25.0)["c1"] == pytest.approx(1500 * (1 - 0.6 * 0.5), rel=0.01)
    assert node.truth(40.0)["c1"] == pytest.approx(600.0, rel=0.01)
    assert node.setup.events["c1_below_70pct"] == pytest.approx(10 + 30 * 0.5)
    al = _decode(node).aligned()
    # the plant really changes: body/wheel relative velocity is damped less at the end
    rel = al.values["x1_dot"] - al.values["x2_dot"]
    n = rel.size // 4
    assert np.std(rel[-n:]) > 1.1 * np.std(rel[:n])


def test_extra_force_hook_changes_the_plant():
    def bump_stop(t, x, u, p):  # a stiff stop when the suspension compresses > 2 cm
        d = x[0] - x[1]
        return np.array([-5e5 * min(0.0, d + 0.02), 5e5 * min(0.0, d + 0.02)])

    cfg = NodeConfig(scenario="bump", duration=1.2, rate=500, noise=0.0)
    plain = _decode(SensorNode(cfg)).aligned()
    hooked = _decode(SensorNode(cfg, extra_forces=[bump_stop])).aligned()
    diff = np.nanmax(np.abs(plain.values["x1"] - hooked.values["x1"]))
    assert diff > 1e-3


def test_fault_injection_shows_up_as_rejections():
    faults = FaultConfig.parse(["loss=0.02", "bitflip=0.01", "late=0.01:0.01", "busoff=1.0:0.1",
                                "burst=1:0.02", "stuck=x1:0.5:0.3"])
    node = SensorNode(NodeConfig(scenario="random", duration=3.0, rate=500, faults=faults, seed=4))
    lst = _decode(node)
    st = lst.frame_stats()
    dropped = node.summary.frames_dropped
    assert st["rejected"]["crc"] == dropped["bitflip"]
    assert st["rejected"]["counter_stale"] >= 0.8 * dropped["late"]
    assert st["lost"] >= dropped["loss"] + dropped["busoff"]
    assert node.summary.busoff_count == 1
    al = lst.aligned()
    x1 = al.values["x1"]
    stuck = (al.t >= 0.5) & (al.t < 0.8) & ~np.isnan(x1)
    assert np.ptp(x1[stuck]) == 0.0 and np.ptp(x1[(al.t > 1.5) & ~np.isnan(x1)]) > 0
    busoff = (al.t >= 1.0) & (al.t < 1.1)
    assert np.isnan(x1[busoff]).all()


@pytest.mark.parametrize("spec, fragment", [
    ("loss=2", "must be in"), ("melt=1", "expected one of"), ("burst=1", "RATE_HZ:LENGTH_S"),
    ("late=0.1:x", "must be a number")])
def test_bad_fault_specs(spec, fragment):
    with pytest.raises(UsageError, match=fragment):
        FaultConfig.parse([spec])


@pytest.mark.realtime
def test_run_on_virtual_bus_paced():
    node = SensorNode(NodeConfig(scenario="bump", duration=1.0, rate=500))
    lst = DecodeListener("quarter2", node.db, time_source="tick")
    with can.Bus(interface="virtual", channel="t-node") as rx, \
            can.Bus(interface="virtual", channel="t-node") as tx:
        notifier = can.Notifier(rx, [lst])
        t0 = time.perf_counter()
        summary = node.run(tx, speed=4.0)
        wall = time.perf_counter() - t0
        time.sleep(0.1)
        notifier.stop()
    assert 0.2 <= wall < 1.0  # 1 s of data at 4x real time
    assert summary.frames_sent == lst.counts.accepted == 4 * 501 + 12
    np.testing.assert_allclose(lst.aligned().t[-1], 1.0)


def test_node_cli_virtual_with_log(tmp_path, capsys):
    log = tmp_path / "node.blf"
    rc = main(["node", "--scenario", "curb", "--duration", "0.5", "--speed", "max",
               "--fault", "bitflip=0.02", "--log", str(log)])
    assert rc == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["node"]
    assert summary["ticks"] == 251 and summary["scenario"] == "curb"
    from estimator.decode import load_log_as_measurement

    meas, stats = load_log_as_measurement(log, "quarter2")
    assert stats["rejected"]["crc"] == summary["frames_dropped"]["bitflip"]
    assert stats["accepted"] + stats["rejected"]["crc"] == summary["frames_sent"]


@pytest.mark.parametrize("argv, fragment", [
    (["--scenario", "flood"], "invalid choice"),
    (["--scenario", "bump", "--interface", "udp_multicast"], "not supported"),
    (["--scenario", "bump", "--channels", "x1,x7"], "x7"),
    (["--scenario", "bump", "--channels", "production,x9"], "or a set (production, accelerometers)"),
    (["--scenario", "bump", "--fault", "stuck=x9:1:1"], "x9"),
    (["--scenario", "bump", "--interface", "nosuchbus"], "cannot open CAN interface"),
])
def test_node_cli_errors_exit_2(capsys, argv, fragment):
    try:
        rc = main(["node"] + argv)
    except SystemExit as exc:  # argparse usage errors
        rc = exc.code
    assert rc == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and fragment in err and "Traceback" not in err


def test_full7_node_log_identifies_the_struts_and_tyres(tmp_path, capsys):
    """The full car end to end: node (FC_* frames) -> log -> identify."""
    log = tmp_path / "full7.log"
    rc = main(["node", "--model", "full7", "--scenario", "random", "--duration", "4",
               "--speed", "max", "--log", str(log)])
    assert rc == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["node"]
    assert summary["model"] == "full7" and summary["frames_sent"] == 2001 * 12 + 42
    m = get_model("full7")
    p = m.defaults()
    fix = [a for k in m.known for a in ("--fix", f"{k}={p[k]}")]
    assert main(["identify", "--model", "full7", "--input", str(log), *fix, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["success"] and out["identifiable"]
    assert out["frames"]["accepted"] == summary["frames_sent"]
    for k in out["stderr"]:
        assert out["params"][k] == pytest.approx(p[k], rel=0.01), k
        assert abs(out["params"][k] - p[k]) < 5 * out["stderr"][k] + 1e-4 * p[k], k


def _virtual_node_run(argv: list[str], channel: str) -> tuple[int, list[can.Message]]:
    """Run ``suspid node`` on a python-can virtual bus and collect every frame it sends."""
    got: list[can.Message] = []
    with can.Bus(interface="virtual", channel=channel) as rx:
        rc = main(["node", "--interface", "virtual", "--channel", channel, *argv])
        while (msg := rx.recv(0.05)) is not None:
            got.append(msg)
    return rc, got


@pytest.mark.parametrize("model_name", list(MODELS))
@pytest.mark.parametrize("named", ["production", "accelerometers"])
def test_node_named_channel_sets_send_only_those_messages(model_name, named, capsys):
    """--channels production: body accelerations and ride heights; accelerometers: every
    coordinate's acceleration; neither sends a road or (production) a wheel message, and the
    decoded values are the plant's within quantization."""
    m = get_model(model_name)
    rc, frames = _virtual_node_run(["--scenario", "damper-wear", "--model", model_name,
                                    "--channels", named, "--speed", "max", "--duration", "5",
                                    "--noise", "0"], f"t-sets-{model_name}-{named}")
    assert rc == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["node"]
    db = load_dbc()
    sig = {ch: (msg, s) for ch, msg, s in channel_signals(db, model_name)}
    want = set(m.channel_set(named))
    expected_msgs = {sig[c][0] for c in want}
    by_id = {db.get_message_by_name(n).frame_id: n for n in expected_msgs}
    sent = {f.arbitration_id for f in frames}
    road_msgs = {sig[c][0] for c in m.input_names}
    wheel_msgs = {sig[c][0] for c in m.channels if c.split("_")[0] not in
                  {m.coords[j] for j in m.body_rows()}}
    assert {db.get_message_by_name(n).frame_id for n in expected_msgs} <= sent
    sent_names = {db.get_message_by_frame_id(i).name for i in sent}
    assert not sent_names & road_msgs
    if named == "production":
        assert not sent_names & wheel_msgs
        assert {sig[d][0] for d in m.ride_heights} <= sent_names
    assert sent_names == expected_msgs | {"SN_Sync", "SN_Status"}
    assert len(frames) == summary["frames_sent"] == 2501 * (1 + len(by_id)) + 52
    # decoded: exactly the set, equal to the plant's truth within half a step
    lst = DecodeListener(m, db)
    feed(lst, frames)
    meas = lst.aligned()
    node = SensorNode(NodeConfig(model=model_name, scenario="damper-wear", duration=5.0,
                                 channels=[named], noise=0.0))
    rows = [node.plant.sample(k) for k in range(node.n_ticks)]
    truth = {c: np.array([r[c] for r in rows]) for c in want}
    assert {c for c, v in meas.values.items() if np.isfinite(v).any()} == want
    for c in want:
        msg, s = sig[c]
        step = db.get_message_by_name(msg).get_signal_by_name(s).scale
        assert np.max(np.abs(meas.values[c] - truth[c])) <= step / 2 * (1 + 1e-6), c
        assert np.ptp(truth[c]) > 20 * step, c   # the channel moves


def test_node_production_quarter2_cli_on_virtual_bus(capsys):
    """The documented run: ride-height and body-acceleration messages, no road message."""
    rc, frames = _virtual_node_run(["--scenario", "damper-wear", "--model", "quarter2",
                                    "--channels", "production", "--speed", "max",
                                    "--duration", "5"], "t-prod-q2")
    assert rc == 0
    db = load_dbc()
    names = {db.get_message_by_frame_id(f.arbitration_id).name for f in frames}
    assert names == {"SN_Sync", "QC_Body", "QC_RideHeight", "SN_Status"}
    body = [db.get_message_by_name("QC_Body").decode(bytes(f.data)) for f in frames
            if f.arbitration_id == db.get_message_by_name("QC_Body").frame_id]
    assert all(b["AccValid"] == 1 and b["DispValid"] == 0 and b["VelValid"] == 0 for b in body)
    rh = [db.get_message_by_name("QC_RideHeight").decode(bytes(f.data)) for f in frames
          if f.arbitration_id == db.get_message_by_name("QC_RideHeight").frame_id]
    assert len(rh) == 2501 and all(r["DispValid"] == 1 and r["VelValid"] == 0 for r in rh)
    assert np.ptp([r["Disp"] for r in rh]) > 1e-3
