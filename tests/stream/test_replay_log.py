"""Replays that check for due windows rarely cut exactly the windows a check per frame cuts.

``suspid monitor --input LOG`` reads the log as arrays and checks for due windows only every
few hundred frames; this must not change a single window, estimate input or counter, on a
clean log and on one with damaged lines, foreign frames and a hole in the data.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from estimator.decode import DecodeListener
from estimator.stream.drivers import CanWindowDriver, replay, replay_log
from estimator.stream.wear_streams import damper_wear, write_log
from tools.corrupt_log import corrupt_candump
from suspid.can.logs import ReadStats, read_log
from suspid.models import get_model


def _windows(path: Path, batch: str, check_every: int) -> tuple[list, dict, int]:
    got: list[tuple[np.ndarray, dict[str, np.ndarray]]] = []
    lst = DecodeListener("quarter2", capacity=1 << 12)
    drv = CanWindowDriver(lst, 3.0, 1.5, lambda t, d: got.append((t.copy(), {k: v.copy() for k, v in d.items()})),
                          check_every=check_every)
    stats = ReadStats()
    if batch == "log":
        n = replay_log(drv, path, stats)
    elif batch == "messages":
        n = replay(drv, read_log(path, stats))
    else:   # the definition: a check after every frame, cut as soon as a window is due
        n = 0
        for msg in read_log(path, stats):
            lst.on_message_received(msg)
            drv.poll()
            n += 1
        drv.flush()
    lst.count_malformed(stats.malformed)
    return got, lst.frame_stats(), n


def _with_hole(src: Path, dst: Path, t_from: float, t_to: float) -> None:
    """Copy a candump log without the frames stamped in [t_from, t_to) (a dead link)."""
    keep = []
    for line in src.read_text().splitlines(keepends=True):
        try:
            t = float(line[1:line.index(")")])
        except ValueError:      # a truncated line: keep it (it is rejected either way)
            t = -1.0
        if not t_from <= t < t_to:
            keep.append(line)
    dst.write_text("".join(keep))


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("replay")
    s = damper_wear(get_model("quarter2"), duration=20.0, wear_start=2.0, seed=5)
    clean = d / "clean.log"
    write_log(s, str(clean))
    damaged = d / "damaged.log"
    corrupt_candump(clean, damaged, truncated=40, corrupted=40, foreign=60, seed=2)
    holed = d / "holed.log"
    _with_hole(damaged, holed, 7.2, 8.1)
    return {"clean": clean, "damaged": damaged, "holed": holed}


@pytest.mark.parametrize("name", ["clean", "damaged", "holed"])
@pytest.mark.parametrize("check_every", [1, 32])
@pytest.mark.parametrize("how", ["log", "messages"])
def test_batch_replay_cuts_the_same_windows(logs: dict[str, Path], name: str, check_every: int,
                                           how: str) -> None:
    """``replay_log`` (arrays) and ``replay`` (messages, the live path's countdown) check for
    due windows only every few hundred frames; the windows equal a check after every frame."""
    ref, ref_stats, ref_n = _windows(logs[name], batch="every frame", check_every=check_every)
    got, stats, n = _windows(logs[name], batch=how, check_every=check_every)
    assert n == ref_n and stats == ref_stats
    assert len(ref) == 12                     # 3 s windows every 1.5 s over 20 s
    assert len(got) == len(ref)
    for (t0, d0), (t1, d1) in zip(ref, got):
        np.testing.assert_array_equal(t1, t0)
        assert d1.keys() == d0.keys()
        for k in d0:
            np.testing.assert_array_equal(d1[k], d0[k])   # NaN where the hole is, on both
    if name == "holed":
        assert sum(np.isnan(d["x1"]).any() for _, d in got) >= 1
    if name != "clean":
        assert sum(stats["rejected"].values()) > 0


def _windows_over_a_dead_link(logs, tmp_path) -> tuple[CanWindowDriver,
                                                     list[tuple[np.ndarray, dict[str, np.ndarray]]]]:
    """The clean log with 6..11 s cut out, replayed through 3 s windows every 1.5 s."""
    holed = tmp_path / "long_hole.log"
    _with_hole(logs["clean"], holed, 6.0, 11.0)
    got: list[tuple[np.ndarray, dict[str, np.ndarray]]] = []
    lst = DecodeListener("quarter2", capacity=1 << 12)
    drv = CanWindowDriver(lst, 3.0, 1.5, lambda t, d: got.append((t.copy(), d)))
    replay_log(drv, holed)
    return drv, got


def test_a_gap_longer_than_a_window_is_skipped_not_fatal(logs, tmp_path) -> None:
    """A dead link of 5 s (longer than the 3 s window) leaves windows without a decoded
    sample: they are skipped and counted, the windows on both sides are cut as before, and
    the replay does not stop with an error."""
    drv, got = _windows_over_a_dead_link(logs, tmp_path)
    ends = [float(t[-1]) for t, _ in got]
    assert drv.empty_windows >= 1
    assert any(e < 6.0 for e in ends) and any(e > 14.0 for e in ends)
    assert not any(9.0 + 0.01 < e < 11.0 for e in ends)   # no window lies inside the hole


def test_windows_reaching_into_a_gap_keep_their_own_span(logs, tmp_path) -> None:
    """A 5 s dead link: the windows that straddle its start or end hold data on one side only.
    One whose data cover less than 80 % of it (``max_missing`` 0.2) is handed over on its
    whole 3 s span, the part in the gap missing (NaN), so the estimator skips it as a gap, at
    its own end time: window ends strictly increase (were: both windows that straddle the
    start of the gap were cut down to their data and reported at the same time, the last
    sample's, the second fitted on half a window with 0 % missing)."""
    _, got = _windows_over_a_dead_link(logs, tmp_path)
    ends = np.array([float(t[-1]) for t, _ in got])
    assert np.all(np.diff(ends) > 1.0)
    straddling = {round(float(t[-1]), 1): (t, d) for t, d in got
                  if t[0] < 6.0 < t[-1] or t[0] - 0.01 < 11.0 < t[-1]}
    assert sorted(straddling) == [7.5, 12.0, 13.5]
    for end, miss in [(7.5, 0.5), (12.0, 2 / 3)]:   # padded to the whole window
        t, d = straddling[end]
        assert t[-1] - t[0] == pytest.approx(3.0, abs=0.01)
        assert np.allclose(np.diff(t), np.diff(t).mean(), rtol=1e-6)   # one uniform grid
        assert float(np.isnan(d["x1"]).mean()) == pytest.approx(miss, abs=0.01)
    t, d = straddling[13.5]   # 2.5 s of data (17 % missing): fitted on them, as before
    assert t[-1] - t[0] == pytest.approx(2.5, abs=0.01) and not np.isnan(d["x1"]).any()
