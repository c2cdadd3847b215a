"""The simulated suspension sensor node (firmware-style).

Modules
-------
node        :class:`SensorNode`: scheduler tasks (sensor, status, rx), CAN driver with faults
scheduler   fixed-rate scheduler with real-time / ``--speed`` pacing
plant       the core's model stepped in chunks (time-varying parameters, extra forces)
scenarios   initial, curb, bump, random road, damper wear
faults      fault injection (loss, bursts, stuck sensor, bit flips, late frames, bus-off)
transport   python-can buses: virtual, slcan (incl. the SLCAN pty adapter), socketcan
"""
