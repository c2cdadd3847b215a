"""The pages of a multiplexed message: validated as one message, each set of pages stored in a
ring of its own (``Chassis[Page=0]``; signals in every frame in the message's ring), all of the
message's group; frames whose multiplexer value is no page of the DBC are counted."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, cast

import numpy as np
from cantools.database.can import Message

from estimator.decode.buffer import Source
from estimator.decode.rules.e2e import Payload
from estimator.decode.vector import RawFn, RowsFn, compile_raw
from suspid.can.codec import MessageCodec

#: payload -> decoded values of one ring's channels
Row = Callable[[Payload], tuple]


@dataclass(eq=False)
class PageSink:
    """The ring of the signals of one set of pages (``mux`` -1: of every frame)."""

    source: Source
    row: Row
    vrow: RowsFn | None
    mux: int
    pages: frozenset[int]

    def __post_init__(self) -> None:
        self._pages_a = np.array(sorted(self.pages), dtype=np.int64)

    def select(self, page: np.ndarray) -> np.ndarray:
        """Mask of the frames (raw multiplexer values ``page``) of this ring's pages."""
        if self._pages_a.size == 1:
            return page == self._pages_a[0]
        return np.isin(page, self._pages_a)


class PageSplit:
    """Store the accepted frames of one multiplexed message page by page (``unknown``: no page)."""

    def __init__(self, msg: Message, muxes: list[str], sinks: list[PageSink]) -> None:
        self.name = msg.name
        self.dlc = msg.length
        self.muxes = tuple(muxes)
        self.sinks = tuple(sinks)
        self.unknown = 0
        codecs = [MessageCodec(msg, [m]) for m in muxes]
        self._raw = [cast(Row, c.unpack_raw) for c in codecs]
        self._vraw: list[RawFn | None] = [compile_raw(c.specs[0], msg.length) for c in codecs]
        defined: list[set[int]] = [set() for _ in muxes]
        for sig in msg.signals:
            if sig.multiplexer_signal in self.muxes and sig.multiplexer_ids:
                defined[self.muxes.index(sig.multiplexer_signal)].update(sig.multiplexer_ids)
        self.defined = tuple(frozenset(d) for d in defined)
        self._defined_a = [np.array(sorted(d), dtype=np.int64) for d in self.defined]

    def push_many(self, t: np.ndarray, rows: np.ndarray) -> None:
        """Store accepted frames (times ``t`` in s, zero-padded payloads ``rows`` (m, max(8, dlc)))."""
        # raw values of each multiplexer
        page = [f(rows) if f is not None else np.array(
            [dec(r.tobytes())[0] for r in rows[:, :self.dlc]], dtype=np.int64)
            for f, dec in zip(self._vraw, self._raw)]
        bad = np.zeros(t.shape[0], dtype=bool)
        for k, p in enumerate(page):
            bad |= ~np.isin(p, self._defined_a[k])
        self.unknown += int(np.count_nonzero(bad))
        for s in self.sinks:
            if s.mux < 0:
                sub, ts = rows, t
            else:
                sel = s.select(page[s.mux])
                if not sel.any():
                    continue
                sub, ts = rows[sel], t[sel]
            if s.vrow is not None:
                vals = s.vrow(sub)
            else:
                vals = np.array([s.row(r.tobytes()) for r in sub[:, :self.dlc]],
                                dtype=np.float64).reshape(sub.shape[0], -1)
            s.source.push_many(ts, vals)
