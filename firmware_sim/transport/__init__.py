"""Buses for the node, all python-can: ``virtual``, ``slcan`` (incl. the pty adapter), ``socketcan``.

:func:`open_bus` (from :mod:`suspid.can.bus`, shared with the estimator) is the one code
path: ``--interface I --channel C`` becomes ``can.Bus(interface=I, channel=C)``, except
``--interface slcan --channel pty``, which creates the simulated SLCAN adapter
(:class:`~firmware_sim.transport.slcan_pty.SlcanPtyBus`) for a second process to attach to.
``udp_multicast`` is refused (no network use).
"""
from __future__ import annotations

from firmware_sim.transport.slcan_pty import SlcanPtyBus
from suspid.can.bus import CHANNEL_FACTORIES, REFUSED, BufferedSlcanBus, open_bus

CHANNEL_FACTORIES[("slcan", "pty")] = SlcanPtyBus

__all__ = ["open_bus", "SlcanPtyBus", "BufferedSlcanBus", "REFUSED"]
