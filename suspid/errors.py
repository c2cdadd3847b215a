"""Exceptions that the command line turns into one ``error: ...`` line and exit status 2."""
from __future__ import annotations


class SuspidError(Exception):
    """Bad usage or unusable input.

    The message must name what is wrong (file, line or frame, field, expected vs got);
    the CLI prints it as ``error: <message>`` and exits with status 2.
    """


class InputError(SuspidError):
    """An input file (CSV, DBC, CAN log, config) cannot be used."""


class UsageError(SuspidError):
    """Command-line options that do not fit together or name unknown things."""
