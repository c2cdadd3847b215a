"""Feeding a monitor: in-memory arrays, a CAN log replayed as fast as possible, a live bus.

All three cut the stream into the same windows: the first ends ``window_s`` after the first
sample, the next ones every ``step_s`` of data time. For CAN input the windows come from the
decoder's bounded rolling buffer (:class:`estimator.decode.DecodeListener`), aligned on a
uniform grid with gaps as NaN; a window is cut once a frame *later* than its end has been
accepted, so every frame of its last sample is in.
"""
from __future__ import annotations

import math
import signal
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping

import numpy as np

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
        Channels to align (default: every mapped channel that carries data in the first
        window -- the set of signals a node sends does not change while it runs).
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
            if self.channels is None:
                # align only what the node actually sends (a QC_Body frame maps x1, x1_dot
                # and x1_ddot; channels never valid in the first window stay out)
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
    from estimator.decode.replay import feed_log

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


def run_bus(driver: CanWindowDriver, bus: Any, stop: LiveStop) -> int:
    """Receive from a live python-can bus until a stop condition; returns frames received.

    Stops on ``stop`` (SIGINT/SIGTERM, duration, idle timeout) or when the bus reports that
    it can no longer be read (``can.CanOperationError``: the adapter or the pty of an SLCAN
    node went away); either way the windows the received frames complete are cut.
    """
    start = time.monotonic()
    last_rx = start
    n = 0
    import can

    while not stop.stop:
        try:
            msg = bus.recv(timeout=0.1)
        except can.CanOperationError as exc:
            # the adapter went away (an SLCAN node closed its pty, a USB-CAN unplugged): the
            # stream has ended; what was received is processed and reported, not lost
            stop.reason = f"bus closed: {' '.join(str(exc).split())}"
            break
        now = time.monotonic()
        if msg is not None:
            driver.on_message(msg)
            n += 1
            last_rx = now
        else:
            driver.poll()
            if stop.idle_timeout is not None and now - last_rx > stop.idle_timeout:
                stop.reason = f"no frame for {stop.idle_timeout:g} s"
                break
        if stop.duration is not None and now - start > stop.duration:
            stop.reason = f"duration {stop.duration:g} s reached"
            break
    driver.flush()
    return n
