"""Feeding a monitor: in-memory arrays, a CAN log replayed as fast as possible, a live bus.

All three cut the same windows: the first ends ``window_s`` after the first sample, the next
every ``step_s`` of data time. CAN windows come from the decoder's bounded buffer
(:class:`estimator.decode.DecodeListener`), cut once a frame later than their end is in.
"""
from __future__ import annotations

import collections
import math
import signal
import socket
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping

import can
import numpy as np

from estimator.decode.buffer import NoSamplesError
from estimator.decode.replay import feed_log
from estimator.stream.accumulator import WindowAccumulator
from suspid.can.bus import LOSS_CLASSES, SocketcanReader
from suspid.can.dbc import is_e2e
from suspid.io.csvio import AUX_CHANNELS
from suspid.models.base import FloatArray

#: default length of the live receiver's buffer (s of data, :func:`receive_capacity`)
RECEIVE_BUFFER_S = 10.0

WindowFn = Callable[[FloatArray, Mapping[str, FloatArray]], Any]


def run_arrays(t: FloatArray, data: Mapping[str, FloatArray], window_s: float, step_s: float,
               on_window: WindowFn, block: int = 1000) -> int:
    """Stream arrays (uniform times ``t``, s) through a :class:`WindowAccumulator` in blocks
    of ``block`` samples, calling ``on_window(t, data)`` per window; returns windows cut."""
    t = np.asarray(t, dtype=float)
    dt = float(np.median(np.diff(t)))
    acc = WindowAccumulator(list(data), int(round(window_s / dt)) + 1, max(1, int(round(step_s / dt))),
                            max_block=block)
    n = 0
    for s in range(0, t.size, block):
        e = min(s + block, t.size)
        for tw, dw in acc.push(t[s:e], {k: v[s:e] for k, v in data.items()}):
            on_window(tw, dw)
            n += 1
    return n


@dataclass
class CanWindowDriver:
    """Cut windows out of a :class:`~estimator.decode.DecodeListener` as frames arrive."""

    listener: Any
    window_s: float
    step_s: float
    on_window: WindowFn  # called with (t, data) per window
    #: channels to align (default: those of the messages that delivered when the first window
    #: starts, which waits up to a window of data time for late ones)
    channels: list[str] | None = None
    check_every: int = 32  # fewest frames between checks of the buffer (next_check)
    frames: int = 0
    windows: int = 0
    empty_windows: int = 0  # windows that held no decoded sample of the channels (skipped)
    dt: float | None = None
    t_first: float = math.nan
    next_end: float = math.nan
    _left: int = 1
    #: a window reaching into a gap and covering less than ``1 - max_missing`` of its span is
    #: padded with NaN, so it is skipped at its own end time
    max_missing: float = 0.2
    _t_seen: float = math.nan
    #: ring -> samples that fell on a grid cell already filled, each counted in the first
    #: window that holds it (:attr:`~estimator.decode.buffer.Aligned.collided`)
    collisions: dict[str, int] = field(default_factory=dict)
    _counted_to: float = -math.inf

    def _sources_started(self, latest: float) -> bool:
        """Every mapped message has delivered, or the start has waited long enough."""
        buf = self.listener.buffer
        srcs = getattr(buf, "sources", None)
        if not isinstance(srcs, dict) or not srcs:
            return True
        if not math.isfinite(self._t_seen):
            # from the oldest sample: frames a decoder held back arrive together
            t0 = buf.earliest_time()
            self._t_seen = t0 if math.isfinite(t0) else latest
        return all(src.n > 0 for src in srcs.values()) or latest - self._t_seen >= self.window_s

    def on_message(self, msg: Any) -> None:
        """Validate/decode one frame (through the listener) and cut due windows."""
        self.listener.on_message_received(msg)
        self.frames += 1
        self._left -= 1
        if self._left <= 0:
            self.poll()
            self._left = self.next_check(self.frames)

    def next_check(self, fed: int, max_steps: float = 0.5) -> int:
        """Frames to take before the next :meth:`poll` after ``fed`` frames: those expected
        before the next window end at the rate seen, at least ``check_every`` and at most
        ``max_steps`` steps' worth (``check_every`` until the first window is placed: it starts
        at the oldest sample whenever the check comes)."""
        every = max(1, self.check_every)
        if not math.isfinite(self.t_first):
            return every
        span = self.listener.buffer.latest_time() - self.t_first
        if not span > 0:
            return every
        rate = fed / span                                  # frames per second of data
        ahead = (self.next_end - self.t_first - span) * rate
        return int(min(max(ahead, every), max(every, max_steps * self.step_s * rate)))

    def poll(self) -> None:
        """Cut every window whose end lies before the newest accepted sample."""
        latest = self.listener.buffer.latest_time()
        if not math.isfinite(latest):
            return
        if not math.isfinite(self.t_first):
            if not self._sources_started(latest):
                return
            if self.channels is None:
                # the vehicle's speed or odometer (mapped for a fleet) is never fitted
                live = [c for name, src in self.listener.buffer.sources.items() if src.n > 0
                        for c in src.channels if c not in AUX_CHANNELS]
                self.channels = live or None
            # the first window starts at the oldest sample
            t0 = self.listener.buffer.earliest_time()
            self.t_first = t0 if math.isfinite(t0) else latest
            self.next_end = self.t_first + self.window_s
        while latest > self.next_end + 1e-9:
            self._cut(self.next_end)
            self.next_end += self.step_s

    def _cut(self, t_end: float) -> None:
        try:
            al = self.listener.aligned(window=self.window_s, t_end=t_end, dt=self.dt,
                                       channels=self.channels)
        except NoSamplesError:
            # a gap in the stream longer than a window: nothing to fit
            self.empty_windows += 1
            return
        for ring, t_col in al.collided.items():
            self.collisions[ring] = (self.collisions.get(ring, 0)
                                     + int(np.count_nonzero(t_col > self._counted_to)))
        self._counted_to = max(t_end, float(al.t[-1]))
        if self.dt is None:
            self.dt = float(al.dt)
            # of the messages that started, the channels that carry data (a node's --channels
            # subset sends the others' validity bits as 0: they stay out)
            live = [c for c, v in al.values.items()
                    if c not in AUX_CHANNELS and np.isfinite(v).any()]
            if live:
                self.channels = live
                al.values = {c: al.values[c] for c in live}
        if al.t.size < 3:
            return
        t, values, dt = al.t, al.values, float(al.dt)
        t_start = t_end - self.window_s
        # a window reaching into a gap: padded with NaN to its span
        if dt > 0 and t[-1] - t[0] + dt < (1.0 - self.max_missing) * (t_end - t_start):
            before = max(0, int(math.floor((t[0] - t_start) / dt + 1e-6)))
            after = max(0, int(math.floor((t_end - t[-1]) / dt + 1e-6)))
            t = np.concatenate([t[0] - dt * np.arange(before, 0, -1), t,
                                t[-1] + dt * np.arange(1, after + 1)])
            values = {c: np.concatenate([np.full(before, np.nan), v, np.full(after, np.nan)])
                      for c, v in values.items()}
        self.on_window(t, values)
        self.windows += 1

    def flush(self) -> None:
        """At the end of the input: cut the windows that the last frames completed."""
        finish = getattr(self.listener, "finish", None)
        if finish is not None:
            finish()
            self.poll()
        latest = self.listener.buffer.latest_time()
        if math.isfinite(latest) and math.isfinite(self.next_end):
            while latest >= self.next_end - 1e-9:
                self._cut(self.next_end)
                self.next_end += self.step_s


def replay(driver: CanWindowDriver, messages: Iterable[Any]) -> int:
    """Feed frames one by one (:meth:`CanWindowDriver.on_message`), flush; returns their number."""
    n = 0
    for msg in messages:
        driver.on_message(msg)
        n += 1
    driver.flush()
    return n


def replay_log(driver: CanWindowDriver, path: Any, stats: Any = None,
               channel: str | None = None) -> int:
    """Replay a CAN log file (``.log``, ``.asc``, ``.blf``, ``.trc``, ``.mf4``) as fast as
    possible, decoded in NumPy batches (:func:`estimator.decode.feed_log`) with the windows
    and statistics of a frame-by-frame :func:`replay`; ``stats`` (ReadStats) is filled,
    ``channel`` selects a bus channel. Returns the number of frames."""
    fed = driver.frames + 1   # frames fed when poll() is called (first after one frame)

    def poll() -> int:
        nonlocal fed
        driver.poll()
        k = driver.next_check(fed, max_steps=1.0)
        fed += k
        return k

    n = feed_log(driver.listener, path, stats, poll=poll, channel=channel)
    driver.frames += n
    driver.flush()
    return n


@dataclass
class LiveStop:
    """Stop conditions of a live run (SIGINT/SIGTERM also stop it cleanly)."""

    duration: float | None = None
    idle_timeout: float | None = 5.0
    stop: bool = False
    reason: str = ""
    _old: dict[int, Any] = field(default_factory=dict)

    def install(self) -> None:
        def handler(signum: int, frame: Any) -> None:
            self.stop = True
            self.reason = f"signal {signal.Signals(signum).name}"
        for s in (signal.SIGINT, signal.SIGTERM):
            try:
                self._old[s] = signal.signal(s, handler)
            except ValueError:  # not in the main thread
                pass

    def restore(self) -> None:
        for s, h in self._old.items():
            signal.signal(s, h)


#: fewest frames per second the receiver's buffer is sized for (a saturated 1 Mbit/s bus
#: carries about 8.5 k frames/s)
RECEIVE_RATE = 10_000.0
#: kernel socket receive buffer asked for on a SocketCAN bus (bytes)
SOCKET_RCVBUF = 8 << 20
#: longest wait (s of frame time) after a loss for each counter-carrying message's next
#: frame, whose counter gap is booked to that loss (:class:`LossLedger`)
LOSS_ATTRIBUTION_S = 1.0


def bus_frame_rate(db: Any) -> float:
    """Frames per second the receiver's buffer is sized for: the DBC's messages at their
    cycle times (``db``: cantools Database or None), at least :data:`RECEIVE_RATE`."""
    cycles = [getattr(msg, "cycle_time", None) for msg in getattr(db, "messages", None) or ()]
    return max(sum(1000.0 / float(c) for c in cycles if c), RECEIVE_RATE)


def receive_capacity(seconds: float, db: Any = None) -> int:
    """Frames the receiver's buffer holds for ``seconds`` of data (:func:`bus_frame_rate`)."""
    return max(1, int(math.ceil(seconds * bus_frame_rate(db))))


def enlarge_socket_buffer(bus: Any) -> int:
    """Ask for a larger kernel receive queue on a SocketCAN bus (``SO_RCVBUFFORCE``, else
    ``SO_RCVBUF``); returns its size (bytes), 0 without a socket."""
    sock = getattr(bus, "socket", None)
    if not isinstance(sock, socket.socket):
        return 0
    for opt in (getattr(socket, "SO_RCVBUFFORCE", 33), socket.SO_RCVBUF):
        try:
            sock.setsockopt(socket.SOL_SOCKET, opt, SOCKET_RCVBUF)
            break
        except OSError:
            continue
    return int(sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF))


class Receiver:
    """Read a python-can bus on its own thread into a buffer of ``capacity`` frames.

    A slow fit on the caller's thread delays the decoding, not the reception. Lost frames
    are counted by cause and each loss is noted in :attr:`events` for :class:`LossLedger`;
    a SocketCAN bus's kernel queue is enlarged (:func:`enlarge_socket_buffer`).
    """

    def __init__(self, bus: Any, capacity: int | None = None) -> None:
        self.bus = bus
        self.capacity = int(capacity) if capacity else receive_capacity(RECEIVE_BUFFER_S)
        self.queue: collections.deque[Any] = collections.deque()
        self.read = 0
        self.queued = 0
        self.overflow = 0
        self.max_queued = 0
        self.error_frames = 0
        self.error: str | None = None
        #: ``(frames queued before it, cause)`` per loss, in order (cause
        #: ``socket_overrun``, ``bus`` or ``buffer_overflow``)
        self.events: collections.deque[tuple[int, str]] = collections.deque()
        try:
            self.reader: SocketcanReader | None = SocketcanReader(bus)
        except (TypeError, OSError):
            self.reader = None
        self.socket_rcvbuf = enlarge_socket_buffer(bus)
        self._dropped = 0
        self._overflowing = False
        self._stop = threading.Event()
        self._ready = threading.Condition()
        self._thread = threading.Thread(target=self._run, name="can-receiver", daemon=True)

    def start(self) -> "Receiver":
        self._thread.start()
        return self

    def _recv(self, timeout: float) -> Any:
        """One frame off the bus (the SocketCAN reader or the bus's own ``recv``)."""
        return self.reader.recv(timeout) if self.reader is not None else self.bus.recv(timeout)

    def _got(self, msg: Any) -> bool:
        """Count one frame read; ``True`` if it is data for the decoder."""
        self.read += 1
        reader = self.reader
        if reader is not None and reader.dropped != self._dropped:
            self._dropped = reader.dropped
            self.events.append((self.queued, "socket_overrun"))
        if msg.is_error_frame:
            self.error_frames += 1
            if reader is not None and LOSS_CLASSES.intersection(reader.last_error):
                self.events.append((self.queued, "bus"))
            return False
        return True

    def _run(self) -> None:
        q = self.queue
        recv = self._recv
        got = self._got
        while not self._stop.is_set():
            try:
                msg = recv(0.1)
            except can.CanOperationError as exc:
                # the adapter went away (an SLCAN node closed its pty, a USB-CAN unplugged)
                self.error = f"bus closed: {' '.join(str(exc).split())}"
                break
            if msg is None or not got(msg):
                continue
            if len(q) >= self.capacity:
                self.overflow += 1
                if not self._overflowing:
                    self._overflowing = True
                    self.events.append((self.queued, "buffer_overflow"))
                continue
            self._overflowing = False
            q.append(msg)
            self.queued += 1
            k = len(q)
            if k > self.max_queued:
                self.max_queued = k
            if k == 1:
                with self._ready:
                    self._ready.notify()
        with self._ready:
            self._ready.notify()

    def take(self, timeout: float) -> list[Any]:
        """Every buffered frame (waits up to ``timeout`` s for one)."""
        q = self.queue
        if not q and self._thread.is_alive():
            with self._ready:
                if not q:
                    self._ready.wait(timeout)
        return [q.popleft() for _ in range(len(q))]

    def drain(self) -> list[Any]:
        """After :meth:`stop`: the buffered frames, then what the kernel still holds."""
        out = self.take(0.0)
        if self.error is not None:
            return out
        while True:
            try:
                msg = self._recv(0.0)
            except (can.CanError, OSError, ValueError):
                break
            if msg is None:
                break
            if self._got(msg):
                out.append(msg)
                self.queued += 1
        return out

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)

    @property
    def socket_overrun(self) -> int | None:
        """Frames the kernel dropped at the full socket queue (``None``: not a SocketCAN bus)."""
        if self.reader is None:
            return None
        now = self.reader.kernel_drops()
        return max(self.reader.dropped, now if now is not None else 0)

    def stats(self) -> dict[str, object]:
        """Frames read off the bus and lost by cause (JSON-ready)."""
        out: dict[str, object] = {
            "read": self.read, "buffer_overflow": self.overflow,
            "socket_overrun": self.socket_overrun, "error_frames": self.error_frames,
            "max_queued": self.max_queued, "buffer_capacity": self.capacity,
            "socket_rcvbuf": self.socket_rcvbuf}
        if self.reader is not None:
            out["bus_errors"] = dict(sorted(self.reader.errors.items()))
        for name in ("adapter_timed", "host_timed"):   # SLCAN: which clock timed the frames
            if isinstance(getattr(self.bus, name, None), int):
                out[name] = getattr(self.bus, name)
        return out


class LossLedger:
    """Which loss the decoder's counter gaps follow, so that no lost frame counts twice.

    After each loss event the ledger books the counter gap found at the first frame of each
    counter-carrying (E2E) message to the event's cause, for at most
    :data:`LOSS_ATTRIBUTION_S` of frame time; gaps found elsewhere (``none``) were lost before
    this receiver saw a loss.
    """

    def __init__(self, listener: Any) -> None:
        self.listener = listener
        self.gaps: collections.Counter[str] = collections.Counter()
        self.cause: str | None = None
        self.until = math.inf
        self.pending: set[int] = set()
        db = getattr(listener, "db", None)
        self._ids = {m.name: int(m.frame_id) for m in getattr(db, "messages", None) or ()
                     if is_e2e(m)}

    def _lost(self) -> int:
        return int(getattr(getattr(self.listener, "counts", None), "lost", 0))

    def event(self, cause: str, t: float) -> None:
        """A loss of ``cause`` before the next frame (its time ``t``, s)."""
        self.cause = cause
        per = getattr(self.listener, "per_message", None)
        seen = per() if callable(per) else {}
        self.pending = {self._ids[name] for name, n in seen.items() if n and name in self._ids}
        self.until = t + LOSS_ATTRIBUTION_S
        if not self.pending:
            self.cause = None

    def feed(self, msgs: list[Any], on: Callable[[Any], None]) -> None:
        """Hand ``msgs`` to ``on`` (the driver), booking the gaps at watched frames."""
        i = 0
        k = len(msgs)
        while self.cause is not None and i < k:
            msg = msgs[i]
            i += 1
            if not msg.timestamp <= self.until:
                self.cause = None
                on(msg)
                break
            if msg.arbitration_id in self.pending:
                self.pending.discard(msg.arbitration_id)
                lost0 = self._lost()
                on(msg)
                self.gaps[self.cause] += self._lost() - lost0
                if not self.pending:
                    self.cause = None
            else:
                on(msg)
        for msg in msgs[i:] if i else msgs:
            on(msg)

    def summary(self, total: int) -> dict[str, int]:
        """Counter gaps by the loss they followed (``none``: no loss event seen)."""
        out = {c: int(self.gaps.get(c, 0)) for c in ("socket_overrun", "bus", "buffer_overflow")}
        out["none"] = max(0, total - sum(out.values()))
        return out


def run_bus(driver: CanWindowDriver, bus: Any, stop: LiveStop,
            buffer_s: float = RECEIVE_BUFFER_S) -> int:
    """Receive from a live bus until ``stop`` (signal, duration, idle) or the bus closes;
    returns frames received. A :class:`Receiver` thread reads, this thread decodes and fits;
    the listener's ``receive_stats`` get the losses by cause (:class:`LossLedger`)."""
    start = time.monotonic()
    last_rx = start
    n = 0
    rx = Receiver(bus, receive_capacity(buffer_s, getattr(driver.listener, "db", None))).start()
    ledger = LossLedger(driver.listener)
    on = driver.on_message
    events = rx.events

    def feed(msgs: list[Any]) -> None:
        nonlocal n
        lo = 0
        while events and events[0][0] < n + len(msgs):
            seq, cause = events.popleft()
            k = max(seq - n, lo)
            ledger.feed(msgs[lo:k], on)
            lo = k
            ledger.event(cause, msgs[k].timestamp)
        ledger.feed(msgs[lo:] if lo else msgs, on)
        n += len(msgs)

    try:
        while True:
            msgs = rx.take(0.1)
            now = time.monotonic()
            if msgs:
                feed(msgs)
                last_rx = now
            else:
                driver.poll()
                if not rx.alive:
                    stop.reason = rx.error or "bus closed"
                    break
                if stop.idle_timeout is not None and now - last_rx > stop.idle_timeout:
                    stop.reason = f"no frame for {stop.idle_timeout:g} s"
                    break
            if stop.stop:
                break
            if stop.duration is not None and now - start > stop.duration:
                stop.reason = f"duration {stop.duration:g} s reached"
                break
    finally:
        rx.stop()
        feed(rx.drain())
        driver.flush()
        rstats = rx.stats()
        gap = int(getattr(getattr(driver.listener, "counts", None), "lost", 0))
        after = ledger.summary(gap)
        rstats["counter_gap"] = gap
        rstats["counter_gap_after"] = after
        rstats["lost_by_cause"] = {
            "buffer_overflow": rx.overflow, "socket_overrun": rstats["socket_overrun"],
            "bus": after["bus"], "counter_gap": after["none"]}
        if isinstance(getattr(driver.listener, "receive_stats", None), dict):
            driver.listener.receive_stats.update(rstats)
    return n
