"""Exceptions that the command line turns into one ``error: ...`` line and exit status 2."""
from __future__ import annotations

import os
from pathlib import Path


class SuspidError(Exception):
    """Bad usage or unusable input; the message names what is wrong (file, line or frame,
    field, expected vs got)."""


class InputError(SuspidError):
    """An input file (CSV, DBC, CAN log, config) cannot be used."""


class UsageError(SuspidError):
    """Command-line options that do not fit together or name unknown things."""


def require_file(path: str | os.PathLike[str], what: str = "file") -> Path:
    """``path`` as a :class:`~pathlib.Path` if it is an existing regular file, else InputError."""
    p = Path(path)
    if p.is_file():
        return p
    if p.is_dir():
        raise InputError(f"{path}: is a directory, expected a {what}")
    raise InputError(f"{path}: no such {what}")
