"""The words of the estimator's options, in a module that imports nothing.

The command line lists them in its help (``suspid X --help`` builds its parser without
loading the estimator); the identifier's modules take them from here.
"""
from __future__ import annotations

#: the output-error cost functions (``--cost``): the seed's sum of squared position
#: differences and the Frobenius norm of the measured-minus-simulated matrix
COSTS: tuple[str, ...] = ("sse", "frobenius")
#: what an identification does with a constant road or position offset (``--offset``)
OFFSET_MODES: tuple[str, ...] = ("remove", "keep")
#: where the road input comes from (``--road``)
ROAD_MODES: tuple[str, ...] = ("measured", "zero", "unknown")
