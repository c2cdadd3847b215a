"""Sensor dropouts: a measured channel blank (NaN) for a stretch of the record.

The data-driven start cuts the gap out of its regression instead of regressing on the
straight line that bridges it, so its estimate stays at the truth and the identification
costs what the record without the gap costs.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from estimator.identify import OutputErrorProblem, Parameters, data_driven_start, fit, \
    fit_from_starts
from estimator.identify.regression import FILL_MAX, SEGMENT_MIN, _segments
from suspid.cli import main
from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement, read_measurement
from suspid.models import get_model
from suspid.simulate import simulate

from ..conftest import TABLE1

#: the wheel's channels are blank from 0.6 s to 1.1 s: half a second of the bump's response
GAP = (0.6, 1.1)


def _blank(meas: Measurement, prefix: str) -> Measurement:
    """``meas`` with every channel starting with ``prefix`` NaN over :data:`GAP`."""
    t = np.asarray(meas.t)
    gap = (t >= GAP[0]) & (t < GAP[1])
    measured = {c: np.where(gap, np.nan, np.asarray(y, dtype=float)) if c.startswith(prefix)
                else np.asarray(y, dtype=float) for c, y in meas.measured.items()}
    return Measurement(t=meas.t, road=meas.road, measured=measured, source=meas.source)


def test_segments_cut_long_gaps_and_bridge_short_ones() -> None:
    """Gaps of up to FILL_MAX samples stay bridged; a longer one splits the record, and a
    stretch shorter than SEGMENT_MIN between two gaps is dropped."""
    missing = np.zeros(1000, dtype=bool)
    assert _segments(missing) == [(0, 2, 1000)]
    missing[100:100 + FILL_MAX] = True
    assert _segments(missing) == [(0, 2, 1000)]
    missing[300:400] = True
    missing[400 + SEGMENT_MIN - 1:500] = True  # a too-short stretch, then a gap
    assert _segments(missing) == [(0, 2, 300), (500, 502, 1000)]


@pytest.mark.parametrize("chans", [["x1", "x2"], ["x1", "x2", "x1_dot", "x2_dot"]])
def test_start_with_a_dropout_is_at_the_truth(chans: list[str]) -> None:
    """Noise-free bump, the wheel's channels blank for 0.5 s of its response: the start is
    within 0.1 % of the truth (it was c1 at 0.001x and k1 at 11x, from the straight line
    across the gap)."""
    m = get_model("quarter2")
    t, road, x0 = make_scenario(m, "bump", duration=3.0, fs=1000.0, params=TABLE1)
    out = simulate(m, TABLE1, t, road, x0)
    meas = _blank(Measurement(t=t, road=road, measured={c: out[c] for c in chans},
                              source="synthetic"), "x2")
    est = data_driven_start(m, meas, fixed={"m1": TABLE1["m1"], "m2": TABLE1["m2"]})
    assert set(est) == {"c1", "k1", "c2", "k2"}
    for k, v in est.items():
        assert v == pytest.approx(TABLE1[k], rel=1e-3), (k, est)


def test_identify_with_a_dropout_costs_what_the_full_record_costs(tmp_path: Path) -> None:
    """``suspid identify`` of a noisy bump with the wheel's channels blank for 0.5 s: the
    evaluation count stays near the full record's (601 against 707; it was 30759 from a
    start at m2 0.8 kg, k2 426 N/m, whose fit slid to m2 0.02 kg and ran every further
    start) and the values agree with the full record's."""
    m = get_model("quarter2")
    csv = tmp_path / "q2.csv"
    assert main(["simulate", "--model", "quarter2", "--scenario", "bump", "--noise", "0.02",
                 "--seed", "1", "--out", str(csv)]) == 0
    full = read_measurement(csv, m)
    results = []
    for meas in (full, _blank(full, "x2")):
        problem = OutputErrorProblem(m, meas)
        params = Parameters.for_model(m, fix={"m1": 300.0}, init={})
        results.append(fit_from_starts(
            problem, params, lambda s, p=problem: fit(p, s, polish=True, multistart=4)[0],
            keep_init=False))
    ref, gapped = results
    assert gapped.success and gapped.identifiable
    assert gapped.nfev <= 1.5 * ref.nfev, (gapped.nfev, ref.nfev)
    assert [s["start"] for s in gapped.starts] == ["data"]
    for k in ("c1", "k1", "m2", "k2"):
        assert gapped.params[k] == pytest.approx(ref.params[k], rel=0.03), k
    # the wheel's damper is the loosest parameter: within its 3-sigma band
    assert abs(gapped.params["c2"] - ref.params["c2"]) < 3 * gapped.stderr["c2"]
