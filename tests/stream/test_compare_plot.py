"""The comparison figure (``suspid compare --plot``): every band and every alert label
readable when the two estimators agree closely."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from estimator.stream.compare import RunRecord, _plot_param


def _record(name: str, sigma: float, alert_t: float) -> RunRecord:
    t = np.arange(1.0, 20.0, 0.5)
    v = 1500.0 - 30.0 * t
    lines = [{"type": "estimate", "t": float(tk), "params": {"c1": float(vk)},
              "stderr": {"c1": sigma}} for tk, vk in zip(t, v)]
    alert = SimpleNamespace(parameter="c1", kind="alert", t=alert_t)
    return RunRecord(name, lines=lines, alerts=[alert], own_track=True)


def test_two_alerts_at_one_time_and_nested_bands_stay_readable() -> None:
    """Both estimators alert at t = 15 s and the NM band lies inside the EKF's: the two
    labels do not overlap, and each band is drawn (filled, hatched apart, with its edges)."""
    fig = Figure(figsize=(9, 3.8))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    recs = [_record("nm", 4.0, 15.0), _record("ekf", 20.0, 15.0)]
    _plot_param(ax, np.arange(0.0, 20.0, 0.5), None, recs, "c1", 1500.0, 0.3)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    labels = [tx for tx in ax.texts if "alert" in tx.get_text()]
    assert [tx.get_text() for tx in labels] == ["NM alert t = 15.0 s", "EKF alert t = 15.0 s"]
    a, b = (tx.get_window_extent(renderer) for tx in labels)
    assert not a.overlaps(b), (a, b)
    bands = [c for c in ax.collections if c.get_label().endswith("+/- 2 stderr")]
    assert len(bands) == 2 and bands[0].get_hatch() != bands[1].get_hatch()
    # the band edges: 2 lines per estimator besides its track
    assert sum(1 for ln in ax.lines if ln.get_linewidth() == 0.6) == 4
