"""Finding the drive logs of a fleet: directories (recursive), glob patterns and files.

Every file whose suffix is a format ``suspid identify`` reads (CAN logs ``.log``, ``.asc``,
``.blf``, ``.trc``, ``.mf4`` and measurement ``.csv``; case-insensitive) is one drive; the
vehicle is the name of the folder that holds it (``fleet/VAN-07/2026-11-02.blf`` belongs to
``VAN-07``).
"""
from __future__ import annotations

import glob
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from estimator.fleet.drive import DRIVE_SUFFIXES
from suspid.errors import InputError


@dataclass(frozen=True)
class DriveFile:
    """A drive log found on disk.

    Attributes
    ----------
    path : str
        As found (absolute if the input was).
    vehicle : str
        Name of the folder holding the file.
    """

    path: str
    vehicle: str


def vehicle_of(path: str | Path) -> str:
    """The vehicle of a log: the name of its folder (of the absolute path if it has none)."""
    p = Path(path)
    name = p.parent.name or p.resolve().parent.name
    return name or "/"


def _is_drive(p: Path) -> bool:
    return p.suffix.lower() in DRIVE_SUFFIXES and not p.name.startswith(".")


def find_drives(inputs: Iterable[str]) -> list[DriveFile]:
    """Every drive log named by ``inputs``, sorted by path, each once.

    Parameters
    ----------
    inputs : iterable of str
        Directories (searched recursively; hidden files and folders skipped), glob
        patterns (``*``, ``?``, ``[...]``, ``**``; a matching directory is searched too) or
        files. An explicitly named file is taken whatever its suffix (identify decides).

    Raises
    ------
    InputError
        An input that is neither an existing path nor a pattern matching anything.
    """
    found: dict[str, DriveFile] = {}

    def add(p: Path) -> None:
        key = str(p)
        if key not in found:
            found[key] = DriveFile(key, vehicle_of(p))

    def walk(d: Path) -> None:
        for q in sorted(d.rglob("*")):
            rel = q.relative_to(d).parts
            if any(part.startswith(".") for part in rel):
                continue
            if q.is_file() and _is_drive(q):
                add(q)

    for item in inputs:
        p = Path(item)
        if p.is_dir():
            walk(p)
        elif p.is_file():
            add(p)
        elif glob.has_magic(item):
            matches = sorted(glob.glob(item, recursive=True))
            if not matches:
                raise InputError(f"--input {item}: the pattern matches no file")
            for m in matches:
                q = Path(m)
                if q.is_dir():
                    walk(q)
                elif q.is_file() and _is_drive(q):
                    add(q)
        else:
            raise InputError(f"--input {item}: no such file or directory")
    return sorted(found.values(), key=lambda d: d.path)
