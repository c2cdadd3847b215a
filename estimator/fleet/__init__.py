"""The fleet: identify every drive log on Dask, keep their history in SQLite, follow each
vehicle's parameters and write a static HTML report (``suspid fleet``; ``docs/fleet.md``).
"""
