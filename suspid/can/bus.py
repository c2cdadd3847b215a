"""Opening python-can buses the same way in the node and the estimator.

``--interface I --channel C`` becomes ``can.Bus(interface=I, channel=C)`` with three
adjustments:

* ``slcan`` + ``pty``: the simulated SLCAN adapter of the sensor node
  (:class:`firmware_sim.transport.slcan_pty.SlcanPtyBus`), for a second process to attach to;
  it registers itself in :data:`CHANNEL_FACTORIES` when :mod:`firmware_sim.transport` is
  imported (this base layer does not import the node);
* ``slcan`` + a device: :class:`BufferedSlcanBus`, python-can's ``slcan`` bus reading the
  serial port in chunks. python-can's reader takes one ``read(1)`` system call per byte
  (~22 per frame), which caps a pty link at 1-3 k frames/s on a busy host -- about the
  2 k frames/s of a 500 Hz quarter-car node; chunked reads lift that 5-7 fold. With
  ``timestamps=True`` it switches the adapter's Lawicel timestamp mode on (``Z1``) and
  gives each frame the adapter's time (ms, wrapping at 60 s, unwrapped here) instead of the
  host's arrival time;
* ``virtual``: ``preserve_timestamps=True`` so a frame keeps the sender's (data) time.

``udp_multicast`` is refused: suspid uses no network transport.
"""
from __future__ import annotations

from typing import Any, Callable, Optional

import can
import serial
from can.interfaces.slcan import slcanBus

from suspid.errors import UsageError

#: interfaces refused on purpose
REFUSED = {"udp_multicast": "a network transport; use virtual, slcan or socketcan"}

#: ``(interface, channel) -> bus factory`` for channels that are not python-can's (the
#: simulated node adapter registers ``("slcan", "pty")``)
CHANNEL_FACTORIES: dict[tuple[str, str], Callable[..., can.BusABC]] = {}

#: Lawicel frame letter -> characters before the payload (letter, ID, DLC digit)
_HEAD = {"t": 5, "r": 5, "T": 10, "R": 10}


def adapter_ms(line: str) -> Optional[int]:
    """The Lawicel timestamp (ms, 0..59999) at the end of a received frame line, if any.

    Parameters
    ----------
    line : str
        ``tIIIL<data><tttt>\r`` and the like.
    """
    body = line.rstrip("\r\a")
    head = _HEAD.get(body[:1])
    if head is None or len(body) < head:
        return None
    try:
        dlc = int(body[head - 1], 16)
    except ValueError:
        return None
    pay = 0 if body[0] in "rR" else 2 * min(dlc, 8)
    if len(body) != head + pay + 4:
        return None
    try:
        return int(body[head + pay:], 16)
    except ValueError:
        return None


class BufferedSlcanBus(slcanBus):
    """python-can's SLCAN bus with a chunked serial reader (same protocol, same options).

    Parameters
    ----------
    timestamps : bool
        Switch the adapter's timestamp mode on (``Z1``) and use its times: frame times are
        the host time of the first timestamped frame plus the adapter's elapsed time (the
        4-digit ms counter unwrapped over its 60 s period). Frames without a timestamp keep
        the host's arrival time.
    **kwargs
        python-can's ``slcan`` options.
    """

    def __init__(self, *args: Any, timestamps: bool = False, **kwargs: Any) -> None:
        self._line = ""
        self._ts_on = timestamps
        self._ts_last = -1
        self._ts_wraps = 0
        self._ts_anchor: Optional[float] = None
        #: frames timed by the adapter / by the host
        self.adapter_timed = 0
        self.host_timed = 0
        super().__init__(*args, **kwargs)
        if timestamps:
            self.close()
            self._write("Z1")
            self.open()

    def _recv_internal(self, timeout: Optional[float]) -> tuple[Optional[can.Message], bool]:
        msg, filtered = super()._recv_internal(timeout)
        if msg is None or not self._ts_on:
            if msg is not None:
                self.host_timed += 1
            return msg, filtered
        ms = adapter_ms(self._line)
        if ms is None:
            self.host_timed += 1
            return msg, filtered
        if self._ts_last >= 0 and ms < self._ts_last - 30000:
            self._ts_wraps += 1          # the 60 s counter wrapped
        self._ts_last = ms
        elapsed = (self._ts_wraps * 60000 + ms) / 1000.0
        if self._ts_anchor is None:
            self._ts_anchor = msg.timestamp - elapsed
        msg.timestamp = self._ts_anchor + elapsed
        self.adapter_timed += 1
        return msg, filtered

    def _read(self, timeout: Optional[float]) -> Optional[str]:
        line = self._read_line(timeout)
        if line is not None:
            self._line = line
        return line

    def _read_line(self, timeout: Optional[float]) -> Optional[str]:
        buf = self._buffer
        port = self.serialPortOrig
        deadline = serial.Timeout(timeout)
        while True:
            i = -1
            for term in (b"\r", b"\a"):
                k = buf.find(term)
                if k >= 0 and (i < 0 or k < i):
                    i = k
            if i >= 0:
                line = buf[: i + 1].decode(errors="replace")
                del buf[: i + 1]
                return line
            try:
                chunk = port.read(max(1, port.in_waiting))
            except (OSError, serial.SerialException) as exc:
                raise can.CanOperationError(f"Could not read from serial device: {exc}") from exc
            if chunk:
                buf.extend(chunk)
                continue
            if deadline.expired():
                return None


def open_bus(interface: str = "virtual", channel: str = "suspid", **kwargs: Any) -> can.BusABC:
    """Open a python-can bus for any suspid component.

    Parameters
    ----------
    interface : str
        python-can interface name (``virtual``, ``slcan``, ``socketcan``, ...).
    channel : str
        Channel; ``pty`` with ``slcan`` creates the simulated node adapter.
    **kwargs
        Passed on to the bus class.

    Raises
    ------
    UsageError
        An interface that is refused, unknown or unavailable, or a channel that cannot be
        opened -- in one line naming both.
    """
    if interface in REFUSED:
        raise UsageError(f"--interface {interface}: not supported ({REFUSED[interface]})")
    try:
        factory = CHANNEL_FACTORIES.get((interface, str(channel).lower().rstrip(":")))
        if factory is not None:
            return factory(**kwargs)
        if interface == "slcan" and str(channel).lower() in ("pty", "pty:"):
            raise UsageError("--interface slcan --channel pty is the simulated sensor node's "
                             "adapter (suspid node); a host opens the node's /dev/pts/N")
        if interface == "slcan":
            return BufferedSlcanBus(channel=channel, **kwargs)
        if interface == "virtual":
            kwargs.setdefault("preserve_timestamps", True)
        return can.Bus(interface=interface, channel=channel, **kwargs)
    except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as exc:
        raise UsageError(f"cannot open CAN interface {interface!r} channel {channel!r}: "
                         f"{' '.join(str(exc).split()) or type(exc).__name__}") from None
