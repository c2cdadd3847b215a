"""The simulated suspension sensor node (firmware-style): ``node`` (tasks and CAN driver),
``scheduler``, ``plant``, ``scenarios``, ``faults``, ``transport`` (python-can buses)."""
