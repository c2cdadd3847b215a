"""The arrival-time fallback: a stream without a sensor clock (no SN_Sync tick) is placed in
its sample slots from the frames' arrival times and their order within each message
(:mod:`estimator.decode.rules.arrival`), so arrival jitter, bursts and delivery delay lose no
frame and change no estimate, and a real gap is still a gap."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from estimator.decode import load_log_as_measurement
from estimator.decode.rules.arrival import arrival_slots, hull_period, place_messages
from suspid.cli import main
from tests.can.test_time_base import FIX, _estimates, _json, _perturbed

P = 0.002
KINDS = ["jitter", "burst", "delay"]


# ---- the rule on synthetic arrival times ---------------------------------------------------
def _arrivals(kind: str, n: int, period: float, gap: tuple[int, int] | None,
              seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Arrival times (s) of a message sampled every ``period`` with ``kind`` transport
    effects, and each frame's true slot; ``gap``: (first missing slot, frames missing)."""
    k = np.arange(n)
    if gap is not None:
        k = np.r_[k[:gap[0]], k[gap[0] + gap[1]:]]
    t = 50.0 + k * period
    rng = np.random.default_rng(seed)
    if kind == "jitter":
        t = np.sort(t + rng.normal(0.0, 0.15 * period, t.size))
    elif kind == "burst":
        t = (np.floor((t - 50.0) / (5 * period) + 1e-9) + 1) * 5 * period + 50.0
    elif kind == "delay":
        t = np.maximum.accumulate(t + rng.exponential(period, t.size))
    return np.round(t, 6), k


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("kind", ["clean", *KINDS])
def test_every_frame_in_its_slot(kind: str, seed: int) -> None:
    t, k = _arrivals(kind, 4000, P, None, seed)
    sl = arrival_slots(t)
    assert sl is not None
    np.testing.assert_array_equal(sl.k, k)
    assert sl.missing == 0 and sl.period == pytest.approx(P, rel=1e-9)
    assert sl.regular == (kind == "clean")
    # arrival is an upper bound on the sample time: no frame placed after it arrived
    # (jitter is symmetric: up to its extremes)
    late = sl.times() - t
    assert late.max() <= (0 if kind != "jitter" else 5 * 0.15 * P) + 1e-9


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("kind", ["clean", *KINDS])
def test_a_real_gap_stays_a_gap(kind: str, seed: int) -> None:
    t, k = _arrivals(kind, 4000, P, (1700, 50), seed)
    sl = arrival_slots(t)
    assert sl is not None and sl.missing == 50
    assert sl.period == pytest.approx(P, rel=1e-9)
    wrong = np.flatnonzero(sl.k != k)
    # arrival times cannot tell on which side of a gap a frame delayed next to it was
    # sampled: at most a burst's worth of frames there
    assert wrong.size <= 5 and (wrong.size == 0 or abs(int(wrong.mean()) - 1700) < 40)


def test_a_period_off_the_microsecond_grid() -> None:
    """The µs rounding applies only within the fit's uncertainty."""
    period = 0.0099945
    t, k = _arrivals("jitter", 6000, period, (2000, 7), 4)
    sl = arrival_slots(t)
    assert sl is not None and sl.missing == 7
    assert sl.period == pytest.approx(period, rel=2e-6) and sl.period != round(period, 6)
    assert np.count_nonzero(sl.k != k) <= 3


def test_hull_period_ignores_bursts_and_delays() -> None:
    for kind in KINDS:
        t, _ = _arrivals(kind, 3000, P, None, 5)
        assert hull_period(t) == pytest.approx(P, rel=2e-3), kind


def test_messages_of_one_rate_share_one_grid() -> None:
    """Frames of one sample in several messages get one time, whatever each one's jitter."""
    slots = []
    for seed in (6, 7, 8):
        t, _ = _arrivals("jitter", 2000, P, None, seed)
        sl = arrival_slots(t)
        assert sl is not None
        slots.append(sl)
    times = place_messages(slots)
    assert all(x is not None for x in times)
    np.testing.assert_array_equal(times[0], times[1])
    np.testing.assert_array_equal(times[0], times[2])


def test_too_few_or_disordered_frames_are_left_alone() -> None:
    assert arrival_slots(np.arange(5) * P) is None
    t = np.arange(100) * P
    t[50] = t[10]
    assert arrival_slots(t) is None
    t = np.arange(100) * P
    t[3] = np.nan
    assert arrival_slots(t) is None


# ---- identify, diagnose, monitor on a stream without a sensor clock ---------------------
@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """8 s of a damper-wear node stream without its SN_Sync frames (no sensor clock: the
    time base is the frames' timestamps), its jitter, burst and delay versions, and a
    jittered version with the frames of 50 consecutive samples missing."""
    d = tmp_path_factory.mktemp("arrival")
    node = d / "node.log"
    assert main(["node", "--scenario", "damper-wear", "--duration", "8", "--wear-start", "2",
                 "--speed", "0", "--log", str(node)]) == 0
    lines = [x for x in node.read_text().splitlines() if " 100#" not in x]   # SN_Sync out
    out = {"clean": d / "clean.log"}
    out["clean"].write_text("\n".join(lines) + "\n")
    for kind in KINDS:
        out[kind] = d / f"{kind}.log"
        _perturbed(out["clean"], out[kind], kind)
    holed = d / "holed.log"
    holed.write_text("".join(x + "\n" for x in lines
                             if not 3.0 - 1e-9 <= float(x[1:x.index(")")]) < 3.1 - 1e-9))
    out["gap"] = d / "gap.log"
    _perturbed(holed, out["gap"], "jitter")
    return out


def _rel(a: dict[str, float], b: dict[str, float]) -> float:
    return max(abs(b[k] / a[k] - 1.0) for k in a)


@pytest.mark.parametrize("kind", KINDS)
def test_no_frame_lost_and_the_data_unchanged(logs: dict[str, Path], kind: str) -> None:
    clean, cs = load_log_as_measurement(logs["clean"], "quarter2")
    got, gs = load_log_as_measurement(logs[kind], "quarter2")
    assert cs["time_base"] == gs["time_base"] == "timestamp"
    assert gs["accepted"] == cs["accepted"] and gs["lost"] == 0
    assert sum(gs["rejected"].values()) == 0                     # type: ignore[attr-defined]
    assert all(v["retimed"] and v["missing"] == 0                # type: ignore[index]
               for v in gs["arrival_slots"].values())            # type: ignore[attr-defined]
    assert not any("already filled" in w or "missing" in w and "samples" in w
                   for w in got.warnings), got.warnings
    assert got.t.size == clean.t.size
    np.testing.assert_allclose(np.diff(got.t), np.diff(clean.t), rtol=1e-9)
    for ch, v in clean.measured.items():
        np.testing.assert_array_equal(got.measured[ch], v)
    # without the slots (nearest grid cell of each timestamp) the same log lost samples
    if kind == "jitter":
        old, _ = load_log_as_measurement(logs[kind], "quarter2", arrival_slots=False)
        assert any("fell on a grid cell already filled" in w for w in old.warnings)


@pytest.mark.slow
@pytest.mark.parametrize("kind", KINDS)
def test_identify_diagnose_monitor_unchanged(logs: dict[str, Path], kind: str,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    # quantization: the clean log's signals are the DBC's integers; the decoded samples
    # are identical (above), so only the time axis could differ: a period within its
    # standard error of 2 ms is taken as 2 ms, and the estimates agree to rounding
    tol = 1e-6
    a = _json(["identify", "--model", "quarter2", "--input", str(logs["clean"]), *FIX, "--json"],
              capsys)
    b = _json(["identify", "--model", "quarter2", "--input", str(logs[kind]), *FIX, "--json"],
              capsys)
    assert b["frames"]["time_base"] == "timestamp"               # type: ignore[index]
    assert _rel(a["params"], b["params"]) <= tol                 # type: ignore[index]
    a = _json(["diagnose", "--model", "quarter2", "--input", str(logs["clean"]), *FIX, "--json"],
              capsys)
    b = _json(["diagnose", "--model", "quarter2", "--input", str(logs[kind]), *FIX, "--json"],
              capsys)
    assert a["effect"] == b["effect"]                            # type: ignore[index]
    assert _rel(a["baseline"]["params"], b["baseline"]["params"]) <= tol   # type: ignore[index]
    mon = ["monitor", "--model", "quarter2", *FIX, "--fix", "c2=300", "--fix", "k2=200000",
           "--window", "2", "--step", "1", "--jsonl", "--no-inspection"]
    ea = _estimates([*mon, "--input", str(logs["clean"])], capsys)
    eb = _estimates([*mon, "--input", str(logs[kind])], capsys)
    assert eb[-1]["frames"]["time_base"] == "timestamp"          # type: ignore[index]
    assert len(ea) == len(eb) >= 6
    for x, y in zip(ea[:-1], eb[:-1]):
        # a constant delivery latency cannot be seen without a sensor clock: the data
        # times are the clean ones shifted by less than a burst
        assert abs(y["t"] - 100.0 - x["t"]) < 5 * P              # type: ignore[operator]
        assert _rel(x["params"], y["params"]) <= tol             # type: ignore[arg-type]


def test_a_real_gap_is_still_reported(logs: dict[str, Path]) -> None:
    meas, stats = load_log_as_measurement(logs["gap"], "quarter2")
    slots = stats["arrival_slots"]
    assert all(v["missing"] == 50 for v in slots.values())      # type: ignore[attr-defined]
    for ch in meas.measured:
        miss = np.isnan(meas.measured[ch])
        assert miss.sum() == 50, ch
        run = np.flatnonzero(miss)
        assert run[-1] - run[0] == 49                             # one run of 50 samples
        assert meas.t[run[0]] - meas.t[0] == pytest.approx(3.0, abs=2 * P)
    assert any("50 samples" in w for w in meas.warnings), meas.warnings


def test_monitor_jsonl_says_the_time_base(logs: dict[str, Path],
                                          capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["monitor", "--model", "quarter2", *FIX, "--window", "2", "--step", "1",
                 "--jsonl", "--no-inspection", "--input", str(logs["burst"])]) == 0
    rows = [json.loads(x) for x in capsys.readouterr().out.splitlines() if x.strip()]
    frames = rows[-1]["frames"]
    assert frames["time_base"] == "timestamp" and frames["arrival_slots"]
