"""Alert logic: confidence bound, persistence, hysteresis, durable log without loss or duplicates."""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimator.alerts import AlertConfig, AlertEngine, AlertStore
from suspid.errors import UsageError

NOM = 1500.0


def engine(store: AlertStore | None = None, **kw) -> AlertEngine:
    cfg = AlertConfig({"c1": NOM}, **{"persistence_s": 2.0, **kw})
    return AlertEngine(cfg, "quarter2", units={"c1": "N s/m"}, store=store)


def feed(eng: AlertEngine, values, stderr, t0: float = 0.0, dt: float = 1.0):
    out = []
    for i, (v, s) in enumerate(zip(values, stderr)):
        out += eng.update(t0 + i * dt, {"c1": v}, {"c1": s})
    return out


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.005, 0.05))
def test_noise_around_nominal_never_alerts(seed: int, rel: float) -> None:
    """Estimates scattered with their honest stderr around any value above the limit: no alert."""
    rng = np.random.default_rng(seed)
    true = NOM * rng.uniform(0.71, 1.2)
    se = rel * true
    vals = true + rng.normal(0, se, 300)
    assert feed(engine(), vals, [se] * 300) == []


def test_confident_drop_alerts_once_after_persistence() -> None:
    eng = engine()
    vals = [1500] * 5 + [1000] * 10          # below the 1050 limit from t=5
    ev = feed(eng, vals, [5.0] * len(vals))
    assert [e.kind for e in ev] == ["alert"]
    a = ev[0]
    assert a.onset == 5.0 and a.t == 7.0      # persistence 2 s of data time
    d = a.to_json()
    for key in ("type", "t", "parameter", "value", "nominal", "message"):
        assert key in d
    assert d["type"] == "alert" and d["parameter"] == "c1" and d["nominal"] == NOM
    assert "70 %" in d["message"] and "c1" in d["message"]


def test_uncertain_estimate_below_limit_does_not_alert() -> None:
    # 1000 +/- 40: upper 99 % bound 1093 > 1050 -> not confident
    assert feed(engine(), [1000] * 30, [40.0] * 30) == []


def test_single_outlier_does_not_alert() -> None:
    vals = [1500] * 5 + [900] + [1500] * 5 + [900, 1500] * 5
    assert feed(engine(), vals, [5.0] * len(vals)) == []


def test_hysteresis_prevents_flapping_and_clears() -> None:
    eng = engine()
    # drop, then hover just above the limit (inside the hysteresis band), then recover
    vals = [1000] * 5 + [1060, 1040, 1070, 1045] * 3 + [1300] * 5
    ev = feed(eng, vals, [3.0] * len(vals))
    assert [e.kind for e in ev] == ["alert", "clear"]
    assert ev[1].t > 16  # cleared only in the recovered part (lower bound > 1125)


def test_nan_or_unidentifiable_window_neither_confirms_nor_resets() -> None:
    eng = engine()
    ev = feed(eng, [1000, float("nan"), 1000, 1000], [5.0, 5.0, 5.0, 5.0])
    assert [e.t for e in ev] == [2.0]


@pytest.mark.parametrize("bad", [dict(drop=0.0), dict(drop=1.0), dict(hysteresis=0.5),
                                 dict(persistence_s=-1)])
def test_bad_config_is_a_usage_error(bad) -> None:
    with pytest.raises(UsageError):
        engine(**bad)


def test_store_is_fsynced_jsonl_and_restart_does_not_duplicate(tmp_path: Path) -> None:
    path = tmp_path / "alerts.jsonl"
    vals = [1500] * 5 + [1000] * 10 + [1400] * 10 + [900] * 10
    se = [5.0] * len(vals)
    store = AlertStore(path)
    first = feed(engine(store), vals[:12], se[:12])   # "killed" after the first alert
    assert [e.kind for e in first] == ["alert"]
    # no close(): the process died; the record must already be on disk
    lines = path.read_text().splitlines()
    assert len(lines) == 1 and json.loads(lines[0])["type"] == "alert"
    # restart and replay the whole stream from the start (a replayed log)
    store2 = AlertStore(path)
    eng2 = engine(store2)
    again = feed(eng2, vals, se)
    kinds = [e.kind for e in again]
    assert kinds == ["clear", "alert"]               # only the events after the crash
    recs = [json.loads(l) for l in path.read_text().splitlines()]
    assert [r["type"] for r in recs] == ["alert", "clear", "alert"]
    assert len({r["id"] for r in recs}) == 3
    assert eng2.suppressed >= 1


def test_live_restart_keeps_the_open_alert(tmp_path: Path) -> None:
    path = tmp_path / "alerts.jsonl"
    feed(engine(AlertStore(path)), [1500] * 3 + [1000] * 5, [5.0] * 8)
    # the monitor restarts while the node keeps running: data time continues, c1 still low
    eng = engine(AlertStore(path))
    assert eng.states["c1"].active
    assert feed(eng, [1000] * 10, [5.0] * 10, t0=20.0) == []
    assert len(path.read_text().splitlines()) == 1


def test_torn_last_line_is_ignored_and_repaired(tmp_path: Path) -> None:
    path = tmp_path / "alerts.jsonl"
    feed(engine(AlertStore(path)), [1500] * 3 + [1000] * 5, [5.0] * 8)
    with open(path, "ab") as fh:
        fh.write(b'{"type": "alert", "t": 99')      # crash in the middle of a write
    store = AlertStore(path)
    assert store.skipped_lines == 1 and len(store.events) == 1
    feed(engine(store), [1400] * 6, [5.0] * 6, t0=30.0)
    lines = path.read_text().splitlines()
    assert json.loads(lines[-1])["type"] == "clear"
    assert all(l.startswith("{") for l in lines)


def test_bus_sink_sends_the_dbc_alert_frame() -> None:
    import can

    from estimator.alerts import BusAlertSink
    from suspid.can.codec import decode_alert
    from suspid.can.crc import e2e_check
    from suspid.can.dbc import load_dbc

    db = load_dbc()
    ch = f"alert-test-{os.getpid()}"
    with can.Bus(interface="virtual", channel=ch) as tx, can.Bus(interface="virtual", channel=ch) as rx:
        eng = engine()
        eng.sinks.append(BusAlertSink(tx, db))
        feed(eng, [1500] * 3 + [1000] * 5, [5.0] * 8)
        msg = rx.recv(1.0)
    assert msg is not None
    assert msg.arbitration_id == db.get_message_by_name("SUSPID_Alert").frame_id
    assert e2e_check(msg.data, msg.arbitration_id)
    d = decode_alert(db, msg.data)
    assert d["parameter"] == "c1" and d["model"] == "quarter2"
    assert d["value"] == pytest.approx(1000.0, abs=0.1) and d["nominal"] == pytest.approx(NOM, abs=0.1)
