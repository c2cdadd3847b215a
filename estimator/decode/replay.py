"""Feeding logged frames to listeners: a direct loop, or a bus for ``can.Notifier``.

A live bus and a replayed log go through the same :meth:`can.Listener.on_message_received`.
For logs, :func:`feed` calls it in a plain loop: ``can.Notifier`` would add a reader thread,
a ``recv`` per frame and a thread hand-off (about 3x slower) and nothing is gained when the
source is a file. :class:`ReplayBus` is the same log as a python-can bus, for code that
wants a Notifier either way (a test checks both paths give identical results).
"""
from __future__ import annotations

import time
from typing import Any, Iterable, Iterator, Optional

import can


def feed(listener: can.Listener, messages: Iterable[can.Message]) -> int:
    """Call ``listener.on_message_received`` for every message; return how many."""
    on = listener.on_message_received
    n = 0
    for msg in messages:
        on(msg)
        n += 1
    return n


class ReplayBus(can.BusABC):
    """A read-only python-can bus that yields the frames of an iterable (e.g. a log).

    Parameters
    ----------
    messages : iterable of can.Message
    channel : str, optional
        Channel name reported by the bus.

    Attributes
    ----------
    exhausted : bool
        ``True`` once every message has been received.
    """

    def __init__(self, messages: Iterable[can.Message], channel: str = "replay",
                 **kwargs: Any) -> None:
        self._it: Iterator[can.Message] = iter(messages)
        self.exhausted = False
        self.channel_info = f"replay of {channel}"
        super().__init__(channel=channel, **kwargs)

    def _recv_internal(self, timeout: Optional[float]) -> tuple[Optional[can.Message], bool]:
        if self.exhausted:
            if timeout:
                time.sleep(min(timeout, 0.01))
            return None, False
        try:
            return next(self._it), False
        except StopIteration:
            self.exhausted = True
            return None, False

    def send(self, msg: can.Message, timeout: Optional[float] = None) -> None:
        raise can.CanOperationError("ReplayBus is read-only")


def feed_with_notifier(listener: can.Listener, messages: Iterable[can.Message],
                       poll: float = 0.05) -> None:
    """Run ``messages`` through ``can.Notifier`` into ``listener`` and wait until done."""
    bus = ReplayBus(messages)
    notifier = can.Notifier(bus, [listener], timeout=poll)
    try:
        while not bus.exhausted:
            time.sleep(poll)
        time.sleep(2 * poll)  # let the notifier thread deliver the last frame
    finally:
        notifier.stop()
        bus.shutdown()
