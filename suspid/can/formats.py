"""The CAN log formats suspid reads and writes, by suffix: tables that import nothing heavy.

:data:`suspid.can.logs.LOG_FORMATS` gives each of these suffixes its reader and writer; the
command line lists the formats from here without loading python-can.
"""
from __future__ import annotations

from pathlib import Path

#: suffix (lower case) -> human name, in the order the help lists them
FORMATS: dict[str, str] = {
    ".log": "candump -L",
    ".asc": "Vector ASC",
    ".blf": "Vector BLF",
    ".trc": "PEAK TRC",
    ".mf4": "ASAM MDF4",
}

#: text formats also read gzip-compressed (``F.asc.gz``), as python-can's ``LogReader`` does
GZIP_READ = (".asc", ".trc")


def log_suffix(path: str | Path, compressed: bool = True) -> str:
    """The format suffix of ``path``, lower case: ``.asc`` for ``F.asc`` and, with
    ``compressed``, for ``F.asc.gz`` (:data:`GZIP_READ`)."""
    p = Path(path)
    suf = p.suffix.lower()
    inner = Path(p.stem).suffix.lower()
    return inner if compressed and suf == ".gz" and inner in GZIP_READ else suf
