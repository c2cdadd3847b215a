"""suspid: identify vehicle suspension parameters (masses, springs, dampers) from sensor data.

The packages and their layers: ``docs/architecture.md``.
"""
__version__ = "0.1.0"
