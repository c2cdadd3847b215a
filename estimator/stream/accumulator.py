"""Bounded window accumulator: the last ``window`` samples of every channel, preallocated.

Blocks of any size go in; a window comes out every ``step`` samples. Memory is fixed
(``2 x window + max_block`` samples per channel); missing samples are NaN.
"""
from __future__ import annotations

from typing import Iterator, Mapping, Sequence

import numpy as np

from suspid.models.base import FloatArray


class WindowAccumulator:
    """Collect samples and yield overlapping windows of ``window`` samples every ``step``
    (``names``: the channels kept; absent ones are NaN; ``max_block``: the buffer's room
    beyond two windows, so that it is compacted once per ``max_block`` samples at most)."""

    def __init__(self, names: Sequence[str], window: int, step: int, max_block: int = 4096) -> None:
        if window < 2 or step < 1:
            raise ValueError(f"window must be >= 2 and step >= 1 samples, got {window}, {step}")
        self.names = list(names)
        self.window = int(window)
        self.step = int(step)
        self.max_block = int(max_block)
        self.capacity = 2 * self.window + self.max_block
        self._t = np.empty(self.capacity)
        self._d = np.full((len(self.names), self.capacity), np.nan)
        self._n = 0            # valid samples in the buffer
        self.total = 0         # samples received
        self._next_end = self.window

    def push(self, t: FloatArray, data: Mapping[str, FloatArray]) -> Iterator[tuple[FloatArray, dict[str, FloatArray]]]:
        """Append a block (increasing times ``t``, s; channel arrays) and yield copies of
        every window ``(t, data)`` it completes."""
        t = np.asarray(t, dtype=float)
        n = t.size
        pos = 0
        while pos < n:
            if self._n + 1 > self.capacity:
                self._compact()
            # copy up to the next window end (so windows are cut exactly)
            until_end = self._next_end - self.total
            take = min(n - pos, self.capacity - self._n, max(until_end, 1))
            a, b = self._n, self._n + take
            self._t[a:b] = t[pos:pos + take]
            for i, name in enumerate(self.names):
                v = data.get(name)
                self._d[i, a:b] = np.nan if v is None else v[pos:pos + take]
            self._n = b
            self.total += take
            pos += take
            if self.total == self._next_end:
                lo = self._n - self.window
                yield (self._t[lo:self._n].copy(),
                       {name: self._d[i, lo:self._n].copy() for i, name in enumerate(self.names)})
                self._next_end += self.step

    def _compact(self) -> None:
        keep = min(self._n, self.window)
        lo = self._n - keep
        self._t[:keep] = self._t[lo:self._n]
        self._d[:, :keep] = self._d[:, lo:self._n]
        self._n = keep
