"""Feeding a monitor: in-memory arrays, a CAN log replayed as fast as possible, a live bus.

All three cut the stream into the same windows: the first ends ``window_s`` after the first
sample, the next ones every ``step_s`` of data time. For CAN input the windows come from the
decoder's bounded rolling buffer (:class:`estimator.decode.DecodeListener`), aligned on a
uniform grid with gaps as NaN; a window is cut once a frame *later* than its end has been
accepted, so every frame of its last sample is in.
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

from estimator.decode.replay import feed_log
from estimator.stream.accumulator import WindowAccumulator
from suspid.models.base import FloatArray

WindowFn = Callable[[FloatArray, Mapping[str, FloatArray]], Any]


def run_arrays(t: FloatArray, data: Mapping[str, FloatArray], window_s: float, step_s: float,
               on_window: WindowFn, block: int = 1000) -> int:
    """Stream arrays through a :class:`WindowAccumulator` in blocks; returns windows cut.

    Parameters
    ----------
    t : ndarray
        Sample times (s), uniform.
    data : mapping
        Channel arrays on ``t``.
    window_s, step_s : float
        Window length and step (s).
    on_window : callable
        Called with ``(t, data)`` of each window.
    block : int
        Samples per pushed block (a decoder batch).
    """
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
    """Cut windows out of a :class:`~estimator.decode.DecodeListener` as frames arrive.

    Parameters
    ----------
    listener : DecodeListener
    window_s, step_s : float
    on_window : callable
        ``(t, data)`` per window.
    channels : list of str
        Channels to align (default: every channel the listener's signal map takes from the
        DBC, whose message has delivered a frame when the first window starts; the first
        window waits up to ``start_wait_s`` of data time for messages that start late, e.g.
        a road message, instead of deciding from whichever frames came first).
    check_every : int
        Fewest frames between checks of the buffer's newest time. Between checks the driver
        takes as many frames as the frame rate seen so far says arrive before the next
        window end, at most half a step's worth (:meth:`next_check`), so the decoder
        validates large batches; a window is aligned from the samples inside it and the
        listener's buffer holds a window plus two steps, so a window cut a little after its
        end is the same window.
    """

    listener: Any
    window_s: float
    step_s: float
    on_window: WindowFn
    channels: list[str] | None = None
    check_every: int = 32
    frames: int = 0
    windows: int = 0
    dt: float | None = None
    t_first: float = math.nan
    next_end: float = math.nan
    _left: int = 1
    on_first_dt: Callable[[float], None] | None = None
    start_wait_s: float | None = None
    _t_seen: float = math.nan

    def _sources_started(self, latest: float) -> bool:
        """Every mapped message has delivered, or the start has waited long enough."""
        buf = self.listener.buffer
        srcs = getattr(buf, "sources", None)
        if not isinstance(srcs, dict) or not srcs:
            return True
        if not math.isfinite(self._t_seen):
            self._t_seen = latest
        if all(src.n > 0 for src in srcs.values()):
            return True
        wait = self.window_s if self.start_wait_s is None else self.start_wait_s
        return latest - self._t_seen >= wait

    def on_message(self, msg: Any) -> None:
        """Validate/decode one frame (through the listener) and cut due windows."""
        self.listener.on_message_received(msg)
        self.frames += 1
        self._left -= 1
        if self._left <= 0:
            self.poll()
            self._left = self.next_check(self.frames)

    def next_check(self, fed: int, max_steps: float = 0.5) -> int:
        """Frames to take before the next :meth:`poll`, after ``fed`` frames in all.

        1 until the first sample is in; then the frames expected before the next window end
        at the rate seen so far (``fed`` over the data time since the first sample), at
        least ``check_every`` and at most ``max_steps`` steps' worth (half a step live, so
        a window is never cut much later than its end; a replay has no such deadline and
        takes up to a whole step: fewer, larger decoder batches).
        """
        if not math.isfinite(self.t_first):
            return 1
        every = max(1, self.check_every)
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
                live = [c for name, src in self.listener.buffer.sources.items() if src.n > 0
                        for c in src.channels]
                self.channels = live or None
            self.t_first = latest
            self.next_end = latest + self.window_s
            return
        while latest > self.next_end + 1e-9:
            self._cut(self.next_end)
            self.next_end += self.step_s

    def _cut(self, t_end: float) -> None:
        al = self.listener.aligned(window=self.window_s, t_end=t_end, dt=self.dt,
                                   channels=self.channels)
        if self.dt is None:
            self.dt = float(al.dt)
            if self.on_first_dt is not None:
                self.on_first_dt(self.dt)
            # of the messages that started, the channels that carry data (a node's --channels
            # subset sends the others' validity bits as 0: they stay out)
            live = [c for c, v in al.values.items() if np.isfinite(v).any()]
            if live:
                self.channels = live
                al.values = {c: al.values[c] for c in live}
        if al.t.size < 3:
            return
        self.on_window(al.t, al.values)
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
    """Feed logged frames as fast as possible; returns the number of frames.

    Same as calling :meth:`CanWindowDriver.on_message` per frame, with the per-frame work
    inlined (the listener call and a countdown to the next window check).
    """
    on = driver.listener.on_message_received
    poll = driver.poll
    n = 0
    left = 1
    for msg in messages:
        on(msg)
        n += 1
        left -= 1
        if left <= 0:
            poll()
            left = driver.next_check(driver.frames + n)
    driver.frames += n
    driver.flush()
    return n


def replay_log(driver: CanWindowDriver, path: Any, stats: Any = None) -> int:
    """Replay a CAN log file as fast as possible; returns the number of frames.

    The log is read and decoded in NumPy batches (:func:`estimator.decode.feed_log`: a
    candump log never becomes :class:`can.Message` objects), checked for due windows where
    :meth:`CanWindowDriver.next_check` says: windows, estimates, alerts and frame statistics
    equal a frame-by-frame :func:`replay` (``tests/stream/test_replay_log.py``).

    Parameters
    ----------
    driver : CanWindowDriver
    path : str or Path
        ``.log``, ``.asc``, ``.blf``, ``.trc`` or ``.mf4``.
    stats : ReadStats, optional
        Filled with frames read and lines skipped.
    """
    fed = driver.frames + 1   # frames fed when poll() is called (first after one frame)

    def poll() -> int:
        nonlocal fed
        driver.poll()
        k = driver.next_check(fed, max_steps=1.0)
        fed += k
        return k

    n = feed_log(driver.listener, path, stats, poll=poll)
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


#: the receiver's buffer in seconds of data at the highest frame rate it is sized for
RECEIVE_BUFFER_S = 5.0
#: frames per second the receiver's buffer is sized for (a saturated 1 Mbit/s CAN bus
#: carries about 8.5 k frames/s; a node at 1 kHz with four messages 4 k)
RECEIVE_RATE = 10_000
#: kernel socket receive buffer asked for on a SocketCAN bus (bytes; a CAN frame costs about
#: 1 kB of it), so the reader thread may be held up a while without the kernel dropping frames
SOCKET_RCVBUF = 8 << 20


def enlarge_socket_buffer(bus: Any, size: int = SOCKET_RCVBUF) -> int:
    """Ask for a larger kernel receive queue on a SocketCAN bus; returns its size (bytes).

    ``SO_RCVBUFFORCE`` (root) passes ``net.core.rmem_max``; otherwise ``SO_RCVBUF`` up to
    it. 0 when the bus has no socket (other interfaces).
    """
    sock = getattr(bus, "socket", None)
    if not isinstance(sock, socket.socket):
        return 0
    for opt in (getattr(socket, "SO_RCVBUFFORCE", 33), socket.SO_RCVBUF):
        try:
            sock.setsockopt(socket.SOL_SOCKET, opt, size)
            break
        except OSError:
            continue
    return int(sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF))


class Receiver:
    """Read a python-can bus on its own thread into a bounded buffer (seconds of data).

    The window fits run on the caller's thread; this thread only takes frames off the
    socket, so a fit that outlasts its step delays the decoding, not the reception, and
    the kernel's socket queue does not overflow. When the buffer is full the newest frame
    is dropped and counted (``buffer_overflow``).

    Parameters
    ----------
    bus : can.BusABC
    capacity : int
        Frames the buffer holds (default ``RECEIVE_BUFFER_S`` x ``RECEIVE_RATE``).
    """

    def __init__(self, bus: Any, capacity: int = int(RECEIVE_BUFFER_S * RECEIVE_RATE)) -> None:
        self.bus = bus
        self.capacity = capacity
        self.queue: collections.deque[Any] = collections.deque()
        self.read = 0
        self.overflow = 0
        self.max_queued = 0
        self.error: str | None = None
        self.socket_rcvbuf = enlarge_socket_buffer(bus)
        self._stop = threading.Event()
        self._ready = threading.Condition()
        self._thread = threading.Thread(target=self._run, name="can-receiver", daemon=True)

    def start(self) -> "Receiver":
        self._thread.start()
        return self

    def _run(self) -> None:
        q = self.queue
        recv = self.bus.recv
        while not self._stop.is_set():
            try:
                msg = recv(0.1)
            except can.CanOperationError as exc:
                # the adapter went away (an SLCAN node closed its pty, a USB-CAN unplugged)
                self.error = f"bus closed: {' '.join(str(exc).split())}"
                break
            if msg is None:
                continue
            self.read += 1
            if len(q) >= self.capacity:
                self.overflow += 1
                continue
            q.append(msg)
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
        n = len(q)
        return [q.popleft() for _ in range(n)]

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)

    def stats(self) -> dict[str, object]:
        """Frames read off the bus and lost by cause (JSON-ready)."""
        return {"read": self.read, "buffer_overflow": self.overflow, "max_queued": self.max_queued,
                "buffer_capacity": self.capacity, "socket_rcvbuf": self.socket_rcvbuf}


def run_bus(driver: CanWindowDriver, bus: Any, stop: LiveStop) -> int:
    """Receive from a live python-can bus until a stop condition; returns frames received.

    A :class:`Receiver` thread reads the bus into a bounded buffer; this thread decodes the
    frames and cuts and fits the windows. Stops on ``stop`` (SIGINT/SIGTERM, duration,
    idle timeout) or when the bus reports that it can no longer be read
    (``can.CanOperationError``: the adapter or the pty of an SLCAN node went away); either
    way every frame received is processed and the windows it completes are cut. The
    listener's frame statistics then carry ``receive``: frames read, frames lost to a full
    buffer, and frames lost on the way (counter gaps: socket overrun or bus loss).
    """
    start = time.monotonic()
    last_rx = start
    n = 0
    rx = Receiver(bus).start()
    on = driver.on_message
    try:
        while True:
            msgs = rx.take(0.1)
            now = time.monotonic()
            for msg in msgs:
                on(msg)
            if msgs:
                n += len(msgs)
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
        for msg in rx.take(0.0):   # what arrived before the thread stopped
            on(msg)
            n += 1
        if rx.error is None:
            # and what the kernel still holds for this socket (a stop while lagging)
            while True:
                try:
                    msg = bus.recv(0.0)
                except (can.CanError, OSError, ValueError):
                    break
                if msg is None:
                    break
                rx.read += 1
                on(msg)
                n += 1
        driver.flush()
        rstats = rx.stats()
        counts = getattr(driver.listener, "counts", None)
        if counts is not None:
            rstats["counter_gap"] = counts.lost
        if isinstance(getattr(driver.listener, "receive_stats", None), dict):
            driver.listener.receive_stats.update(rstats)
    return n
