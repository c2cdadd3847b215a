"""Opening python-can buses the same way in the node and the estimator.

``--interface I --channel C`` becomes ``can.Bus(interface=I, channel=C)`` with three
adjustments:

* ``slcan`` + ``pty``: the simulated SLCAN adapter of the sensor node
  (:class:`firmware_sim.transport.slcan_pty.SlcanPtyBus`), for a second process to attach to;
* ``slcan`` + a device: :class:`BufferedSlcanBus`, python-can's ``slcan`` bus reading the
  serial port in chunks. python-can's reader takes one ``read(1)`` system call per byte
  (~22 per frame), which caps a pty link at 1-3 k frames/s on a busy host -- about the
  2 k frames/s of a 500 Hz quarter-car node; chunked reads lift that 5-7 fold;
* ``virtual``: ``preserve_timestamps=True`` so a frame keeps the sender's (data) time.

``udp_multicast`` is refused: suspid uses no network transport.
"""
from __future__ import annotations

from typing import Any, Optional

import can
from can.interfaces.slcan import slcanBus

from suspid.errors import UsageError

#: interfaces refused on purpose
REFUSED = {"udp_multicast": "a network transport; use virtual, slcan or socketcan"}


class BufferedSlcanBus(slcanBus):
    """python-can's SLCAN bus with a chunked serial reader (same protocol, same options)."""

    def _read(self, timeout: Optional[float]) -> Optional[str]:
        import serial

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
        if interface == "slcan" and str(channel).lower() in ("pty", "pty:"):
            from firmware_sim.transport.slcan_pty import SlcanPtyBus

            return SlcanPtyBus(**kwargs)
        if interface == "slcan":
            return BufferedSlcanBus(channel=channel, **kwargs)
        if interface == "virtual":
            kwargs.setdefault("preserve_timestamps", True)
        return can.Bus(interface=interface, channel=channel, **kwargs)
    except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as exc:
        raise UsageError(f"cannot open CAN interface {interface!r} channel {channel!r}: "
                         f"{' '.join(str(exc).split()) or type(exc).__name__}") from None
