"""Short soak: 25 s of simulated stream at speed through decoder, windows and identifier.

A shortened ``tools/soak.py`` (the 1-hour figures are in docs/robustness.md): RSS must not
trend upwards once the rings (4096 rows per message, 8 s at 500 Hz, so they wrap three
times) and the identifier are warm. The bound is loose (RSS moves by allocator pages); a
leak of the frames or of the window results (~50 k frames, 16 windows) would exceed it.
No timing assertions: the host is shared.
"""
from __future__ import annotations

import math

import pytest

from tools.soak import soak


@pytest.mark.slow
def test_short_soak_memory_is_flat() -> None:
    rows = soak(duration=25.0, report_every=2.5, capacity=4096, identify=True)
    assert len(rows) == 10
    assert rows[-1]["frames"] > 48000
    windows = sum(r["windows"] for r in rows)
    assert windows >= 14  # the monitor's quarter2 windows (3 s every 1.5 s) were identified
    assert all(math.isfinite(r["c1"]) for r in rows[2:])
    rss = [r["rss_mb"] for r in rows]
    warm = rss[3]  # after 10 s: every ring has wrapped at least once
    assert max(rss[3:]) - warm < 6.0, rss
    # no upward trend: the last third no higher than the middle third (+ allocator slack)
    assert sum(rss[-3:]) / 3 - sum(rss[3:6]) / 3 < 3.0, rss
