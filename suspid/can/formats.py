"""The CAN log formats suspid reads and writes, by suffix: a table that imports nothing.

:data:`suspid.can.logs.LOG_FORMATS` gives each of these suffixes its reader and writer; the
command line lists the formats from here without loading python-can.
"""
from __future__ import annotations

#: suffix (lower case) -> human name, in the order the help lists them
FORMATS: dict[str, str] = {
    ".log": "candump -L",
    ".asc": "Vector ASC",
    ".blf": "Vector BLF",
    ".trc": "PEAK TRC",
    ".mf4": "ASAM MDF4",
}
