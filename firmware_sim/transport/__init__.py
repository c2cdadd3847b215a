"""Buses for the node, all python-can, through :func:`suspid.can.bus.open_bus`;
``--interface slcan --channel pty`` creates the simulated SLCAN adapter
(:class:`~firmware_sim.transport.slcan_pty.SlcanPtyBus`)."""
from __future__ import annotations

from firmware_sim.transport.slcan_pty import SlcanPtyBus
from suspid.can.bus import CHANNEL_FACTORIES, REFUSED, BufferedSlcanBus, open_bus

CHANNEL_FACTORIES[("slcan", "pty")] = SlcanPtyBus

__all__ = ["open_bus", "SlcanPtyBus", "BufferedSlcanBus", "REFUSED"]
