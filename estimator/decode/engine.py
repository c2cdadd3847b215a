"""The decoder's engine: batches of frames -> validated, decoded samples in the rolling buffer.

:meth:`DecodeEngine.process` takes every batch, of any size (a log's chunks, a live bus's
queue, one frame): the time order and the stateless checks (ID, DLC, CRC) over the whole
batch, then per message the counter rules, which for steady frames reduce to the period
recurrence; from a message's first irregular frame in the batch (a counter gap, a stale
tick) its frames step through the sequential rules one by one. No lock: the listener
serialises calls.
"""
from __future__ import annotations

from bisect import bisect_left

import numpy as np
from cantools.database.can import Database

from estimator.decode.routes import DATA, STATUS, SYNC, Route, Routes
from estimator.decode.rules.counters import CounterRules, FrameCounts, period_after, steady_frames
from estimator.decode.rules.e2e import Payload, alive_counters, crc_ok_rows
from estimator.decode.rules.timebase import (SyncTrack, TickClock, TimeOrder, fresh_ticks, stale_tick,
                                             sync_times, tick_times, ticks_of_counters)
from suspid.can.codec import decode_alert
from suspid.can.crc import COUNTER_MODULUS
from suspid.can.logs import FrameArrays

#: stateless outcome of a frame in a batch (0: passed ID, DLC and CRC)
_O_UNKNOWN, _O_IGNORED, _O_DLC, _O_CRC = 1, 2, 3, 4


class DecodeEngine:
    """Validate, decode and store frames; the state that carries from frame to frame."""

    def __init__(self, db: Database, routes: Routes, *, tick_time: bool, max_counter_delta: int,
                 collect_alerts: bool) -> None:
        self.db = db
        self.routes = routes
        self.counts = FrameCounts()
        self._rejected = self.counts.rejected
        self.counters = CounterRules(self.counts, max_counter_delta)
        self.order = TimeOrder()
        self.tick_time = tick_time
        self.sync_tick: int | None = None
        self.sync_shift = 0
        self.clock = TickClock()
        self.sync_n = 0
        self.period: float | None = None
        self.node_status: dict[str, object] = {}
        self.alerts: list[dict[str, object]] = []
        self.collect_alerts = collect_alerts
        self.outbox: list[dict[str, object]] = []
        self.frames = 0
        #: the batch being processed and its rows' indices in it (CAN FD payloads only)
        self._long: tuple[FrameArrays, np.ndarray] | None = None

    def _special(self, route: Route, data: Payload, ts: float) -> bool:
        """An accepted SN_Status or SUSPID_Alert frame; ``False`` if rejected."""
        if route.kind == STATUS:
            state, rate, flags, busoff, sset = route.decode(data)
            self.node_status = {"t": ts, "state": int(state), "sample_rate": float(rate),
                                "fault_flags": int(flags), "busoff_count": int(busoff),
                                "sensor_set": int(sset)}
        else:
            try:
                alert = decode_alert(self.db, data)
            except Exception:  # an unknown ParamKind: a corrupted but CRC-valid alert
                self._rejected["crc"] += 1
                return False
            alert["t"] = ts
            self.alerts.append(alert)
            if self.collect_alerts:
                self.outbox.append(alert)
        return True

    def process(self, fa: FrameArrays, lo: int, hi: int) -> None:
        """Validate, decode and store frames ``lo:hi`` of ``fa`` (any number, from one up)."""
        n = hi - lo
        if n <= 0:
            return
        self.frames += n
        ft = fa.frame_type[lo:hi]
        sel: slice | np.ndarray = slice(lo, hi)
        if ft.any():
            kept = np.flatnonzero(~ft) + lo
            self._rejected["frame_type"] += n - kept.size
            if not kept.size:
                return
            sel = kept
        ts = fa.timestamp[sel]
        keep = self.order.admit(ts)
        if not keep.all():
            self._rejected["time"] += int(keep.size - np.count_nonzero(keep))
            if not keep.any():
                return
            sel = (np.arange(lo, hi) if isinstance(sel, slice) else sel)[keep]
            ts = ts[keep]
        m = ts.size
        data64 = np.ascontiguousarray(fa.data).view(np.uint64).reshape(-1)
        fid = fa.arbitration_id[sel]
        ext = fa.is_extended[sel]
        length = fa.length[sel]
        rows = data64[sel]
        rt = self.routes   # the stateless checks: outcome per frame
        keys = fid | (ext.astype(np.int64) << 31) if ext.any() else fid
        rkeys = rt.keys   # never empty: a decoder has at least one data message
        p = np.searchsorted(rkeys, keys)
        p[p >= rkeys.size] = 0
        hit = rkeys[p] == keys
        r = rt.num[p]
        outcome = np.zeros(m, dtype=np.int8)
        if not hit.all():
            miss = ~hit
            known = np.isin(keys, rt.ignored_keys) if rt.ignored_keys.size \
                else np.zeros(m, bool)
            outcome[miss] = np.where(known[miss], _O_IGNORED, _O_UNKNOWN)
            r = np.where(hit, r, -1)
        rdlc = rt.dlc[r]
        bad = hit & (length != rdlc)
        if bad.any():
            outcome[bad] = _O_DLC
        self._long = None
        if fa.long_data:   # CAN FD payloads: the whole payload from the batch
            self._long = (fa, np.arange(lo, hi) if isinstance(sel, slice) else sel)
        e2e = rt.e2e[r] & (outcome == 0)
        if e2e.any():
            wide = e2e & (rdlc > 8)
            ok = crc_ok_rows(rows.view(np.uint8).reshape(m, 8), rt.start[r], rdlc, e2e & ~wide)
            if wide.any():
                at = np.flatnonzero(wide)
                ok[at] = crc_ok_rows(self._wide(at, int(rdlc[at].max())), rt.start[r[at]],
                                     rdlc[at], np.ones(at.size, dtype=bool))
            outcome[~ok] = _O_CRC
        self._segment(ts, r, outcome, rows)
        self._long = None

    def _wide(self, q: np.ndarray, width: int) -> np.ndarray:
        """Whole payloads (``width`` bytes, zero-padded) of the batch's frames at ``q``."""
        out = np.zeros((q.size, width), dtype=np.uint8)
        if self._long is not None:
            fa, at = self._long
            for j, i in enumerate(at[q].tolist()):
                p = fa.payload(i)[:width]
                out[j, :len(p)] = np.frombuffer(p, dtype=np.uint8)
        return out

    def _payloads(self, route: Route, rows: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Payloads (m, max(8, dlc)) uint8 of one message's frames at ``q`` (``rows``: uint64)."""
        if route.dlc > 8:
            return self._wide(q, route.dlc)
        return rows.view(np.uint8).reshape(rows.size, 8)

    def _segment(self, ts: np.ndarray, r: np.ndarray, outcome: np.ndarray,
                 rows: np.ndarray) -> None:
        """Frames in time order (times ``ts``, routes ``r``, stateless ``outcome``, payloads
        ``rows`` as uint64): counter rules by message, then stored."""
        if outcome.any():
            cnt = np.bincount(outcome, minlength=5).tolist()
            rejected = self._rejected
            rejected["unknown_id"] += cnt[_O_UNKNOWN]
            self.counts.ignored += cnt[_O_IGNORED]
            rejected["dlc"] += cnt[_O_DLC]
            rejected["crc"] += cnt[_O_CRC]
            h = np.flatnonzero(outcome == 0)
            if not h.size:
                return
            r_h = r[h]
        else:
            h = None
            r_h = r
        route_list = self.routes.ordered
        nroutes = len(route_list)
        if r_h.size > 1 and (r_h[1:] < r_h[:-1]).any():
            order = np.argsort(r_h.astype(np.uint8 if nroutes < 256 else np.uint16),
                               kind="stable")
            h = order if h is None else h[order]
            r_h = r_h[order]
        elif h is None:
            h = np.arange(ts.size)
        rows = rows[h]
        arr = ts[h]
        cnt_r = np.bincount(r_h, minlength=nroutes)
        ends = np.cumsum(cnt_r).tolist()
        runs = [(k, ends[k] - c, ends[k]) for k, c in enumerate(cnt_r.tolist()) if c]
        syncs = SyncTrack(self.sync_tick, self.sync_n, self.period, self.sync_shift) \
            if self.tick_time else None
        tsd = arr
        if syncs is not None and route_list[runs[0][0]].kind == SYNC:
            # tick mode: SN_Sync first (its data time is its own Tick x PeriodUs)
            k, a, b = runs[0]
            route = route_list[k]
            b8 = self._payloads(route, rows[a:b], h[a:b])
            tk, pus = self._sync_values(route, b8)
            t_s = arr[a:b]
            if route.e2e:
                # the unbroken tick across wraps and node restarts (TickClock)
                raw = tk
                tk = self.clock.extend_many(raw, pus, t_s)
                syncs.pending_shifts = (tk - raw) % COUNTER_MODULUS
                t_s = sync_times(tk, pus, t_s)
                acc = self._runs(runs[:1], rows, arr, t_s, a, syncs)
            else:
                acc = np.ones(b - a, dtype=bool)
            self._accepted(route, b8, t_s, acc, (tk, pus), syncs, h[a:b])
            runs = runs[1:]
            if not runs:
                return
        if syncs is not None:
            # the SN_Sync state each other frame sees, and the data time of the E2E frames
            a0 = runs[0][1]
            sn, st, known, per, shift = syncs.at(h[a0:])
            syncs.sn, syncs.known, syncs.per, syncs.lo = sn, known, per, a0
            has = known & ~np.isnan(per)
            conv = has & self.routes.data_e2e[r_h[a0:]]
            at_sync = has & self.routes.tick_e2e[r_h[a0:]]
            tsd = arr
            if conv.any() or at_sync.any():
                tk = np.where(conv, ticks_of_counters(
                    st, (alive_counters(rows[a0:]) + shift) % COUNTER_MODULUS), st)
                tsd = arr.copy()
                tsd[a0:] = np.where(conv | at_sync, tick_times(tk, per), arr[a0:])
        e2e_runs = [x for x in runs if route_list[x[0]].e2e]
        if e2e_runs:
            a0, b0 = e2e_runs[0][1], e2e_runs[-1][2]
            acc = self._runs(e2e_runs, rows, arr, tsd[a0:b0], a0, syncs)
            for k, a, b in e2e_runs:
                self._accepted(route_list[k], self._payloads(route_list[k], rows[a:b], h[a:b]),
                               tsd[a:b], acc[a - a0:b - a0], None, syncs, h[a:b])
        for k, a, b in runs:
            route = route_list[k]
            if route.e2e:
                continue
            # not E2E protected: no counter, the data time is the frame time
            if route.kind == DATA and syncs is not None:
                self._rejected["no_sync"] += b - a
                continue
            b8 = self._payloads(route, rows[a:b], h[a:b])
            sync_vals = self._sync_values(route, b8) if syncs is not None and \
                route.kind == SYNC else None
            self._accepted(route, b8, arr[a:b], np.ones(b - a, dtype=bool), sync_vals, syncs,
                           h[a:b])

    def _runs(self, runs: list[tuple[int, int, int]], rows: np.ndarray, arr: np.ndarray,
              tsd: np.ndarray, lo: int, syncs: SyncTrack | None) -> np.ndarray:
        """Counter and period rules of consecutive message runs; the accepted mask."""
        hi = runs[-1][2]
        m = hi - lo
        routes = self.routes.ordered
        c = alive_counters(rows[lo:hi])
        starts = np.array([a - lo for _, a, _ in runs], dtype=np.int64)
        last_c = np.array([routes[r].last_c for r, _, _ in runs], dtype=np.int64)
        good, el, rid = steady_frames(c, tsd, starts, last_c,
                                      np.array([routes[r].last_ts for r, _, _ in runs]),
                                      np.array([routes[r].period for r, _, _ in runs]))
        fresh = starts[last_c < 0]          # first frame ever of its message
        is_data = np.array([routes[r].kind == DATA for r, _, _ in runs])
        if syncs is not None and is_data.any():
            # tick mode: a known tick and period, and no stale tick
            o = lo - syncs.lo
            sn = syncs.sn[o:o + m]
            per = syncs.per[o:o + m]
            known = syncs.known[o:o + m]
            prev_sn = np.empty(m, dtype=np.int64)
            prev_sn[1:] = sn[:-1]
            prev_sn[starts] = [routes[r].sync_n for r, _, _ in runs]
            prev_a = np.empty(m)
            prev_a[1:] = arr[lo:hi - 1]
            prev_a[starts] = [routes[r].last_arrival for r, _, _ in runs]
            ok = fresh_ticks(sn, prev_sn, arr[lo:hi], prev_a, per, known)
            ok[fresh] = known[fresh] & ~np.isnan(per[fresh])
            good &= ok | ~is_data[rid]
        bad = np.flatnonzero(~good).tolist()
        acc = np.ones(m, dtype=bool)
        # the fast prefix of every run: [s0 + skip, fb) of el feeds the period estimate
        fast: list[tuple[int, int, int, int]] = []
        for r, a, b in runs:
            s0, s1 = a - lo, b - lo
            fb = s1
            if bad:
                k = bisect_left(bad, s0)
                if k < len(bad) and bad[k] < s1:
                    fb = bad[k]
            fast.append((r, s0, s1, fb))
        periods = period_after([(routes[r].period, s0 + (1 if routes[r].last_c < 0 else 0), fb)
                                for r, s0, _, fb in fast], el)
        for (r, s0, s1, fb), p in zip(fast, periods):
            route = routes[r]
            n_fast = fb - s0
            if n_fast:
                route.period = p
                route.last_c = int(c[fb - 1])
                route.last_ts = float(tsd[fb - 1])
                if syncs is not None:   # tick mode
                    route.last_arrival = float(arr[lo + fb - 1])
                    route.sync_n = syncs.n0 + n_fast - 1 if route.kind == SYNC else \
                        int(syncs.sn[lo + fb - 1 - syncs.lo])
            if fb < s1:
                acc[fb:s1] = self._route_rest(route, c[fb:s1].tolist(), tsd[fb:s1].tolist(),
                                              arr[lo + fb:lo + s1].tolist(), n_fast,
                                              lo + fb, syncs)
        return acc

    def _route_rest(self, route: Route, cl: list[int], tl: list[float], al: list[float],
                    n_before: int, at: int, syncs: SyncTrack | None) -> np.ndarray:
        """The rules of :meth:`validate` for frames of one message, one by one; accepted mask."""
        rejected = self._rejected
        step = self.counters.step
        tick = syncs is not None
        is_data = route.kind == DATA
        is_sync = route.kind == SYNC
        n = len(cl)
        acc = np.zeros(n, dtype=bool)
        if syncs is not None:   # tick mode
            o = at - syncs.lo
            if is_sync:
                sn_sync = syncs.n0 + n_before
            else:
                snl = syncs.sn[o:o + n].tolist()
                perl = syncs.per[o:o + n].tolist()
                knownl = syncs.known[o:o + n].tolist()
        for k in range(n):
            ck = cl[k]
            t = tl[k]
            if tick:
                sn = sn_sync if is_sync else snl[k]
                if is_data and knownl[k] and perl[k] == perl[k]:   # tick and period known
                    if stale_tick(route, sn, perl[k], al[k]):
                        rejected["no_sync"] += 1
                        continue
                route.last_arrival = al[k]
                route.sync_n = sn
            if not step(route, ck, t):
                continue
            if tick and is_data and not knownl[k]:
                rejected["no_sync"] += 1
                continue
            acc[k] = True
            if tick and is_sync:
                sn_sync += 1
        return acc

    def _sync_values(self, route: Route, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(Tick, PeriodUs)`` of SN_Sync payloads (int64 arrays, or int64 and float64)."""
        if route.vsync is not None:
            return route.vsync(rows)
        vals = [route.decode(r.tobytes()) for r in rows[:, :route.dlc]]
        return (np.array([int(v[0]) for v in vals], dtype=np.int64),
                np.array([v[1] for v in vals], dtype=np.float64))

    def _accepted(self, route: Route, rows: np.ndarray, tsd: np.ndarray,
                  acc: np.ndarray, sync_vals: tuple[np.ndarray, np.ndarray] | None,
                  syncs: SyncTrack | None, q: np.ndarray) -> None:
        """Decode and store (data) or apply (SN_Sync, SN_Status, alert) the accepted frames ``acc``."""
        n_acc = int(np.count_nonzero(acc))
        if not n_acc:
            return
        kind = route.kind
        if kind == DATA:
            if n_acc < acc.size:
                rows = rows[acc] if rows.shape[1] > 8 else \
                    rows.view(np.uint64).reshape(-1)[acc].view(np.uint8).reshape(n_acc, 8)
                tsd = tsd[acc]
            if route.source is None or route.row is None:
                if route.pages is None:   # every DATA route has a source and a decoder, or pages
                    raise RuntimeError(f"data route {route.name} without a source or decoder")
                route.pages.push_many(tsd, rows)   # a multiplexed message: page by page
            else:
                if route.vrow is not None:
                    vals = route.vrow(rows)
                else:
                    L = route.dlc
                    vals = np.array([route.row(r.tobytes()) for r in rows[:, :L]],
                                    dtype=np.float64).reshape(n_acc, -1)
                route.source.push_many(tsd, vals)
        elif kind == SYNC:
            at = np.flatnonzero(acc)
            if sync_vals is None:   # timestamp mode: only the last frames matter
                tick, _ = route.decode(rows[at[-1], :route.dlc].tobytes())
                self.sync_tick = int(tick)
                for i in at[::-1].tolist():
                    _, period_us = route.decode(rows[i, :route.dlc].tobytes())
                    if period_us > 0:
                        self.period = period_us * 1e-6
                        break
            else:
                if syncs is None:   # sync_vals are computed in tick mode only
                    raise RuntimeError("SN_Sync values without the tick-mode sync state")
                tk, pus = sync_vals
                tk_acc, pus_acc = tk[at], pus[at]
                shifts = None if syncs.pending_shifts is None else syncs.pending_shifts[at]
                syncs.pending_shifts = None
                syncs.add(q[at], tk_acc, pus_acc, shifts)
                self.sync_tick = int(tk_acc[-1])
                self.sync_shift = 0 if shifts is None else int(shifts[-1])
                pos = np.flatnonzero(pus_acc > 0)
                if pos.size:
                    self.period = pus_acc[pos[-1]].item() * 1e-6
            self.sync_n += n_acc
        elif kind == STATUS:
            i = int(np.flatnonzero(acc)[-1])   # the last status only
            self._special(route, rows[i, :route.dlc].tobytes(), float(tsd[i]))
        else:
            for i in np.flatnonzero(acc).tolist():
                if not self._special(route, rows[i, :route.dlc].tobytes(), float(tsd[i])):
                    n_acc -= 1
        route.accepted += n_acc
        self.counts.accepted += n_acc

