"""Finding the drive logs of a fleet: directories (recursive), glob patterns and files.

Every file whose suffix is a format ``suspid identify`` reads (CAN logs ``.log``, ``.asc``,
``.blf``, ``.trc``, ``.mf4``, gzip-compressed ``.asc.gz``, ``.trc.gz``, and measurement ``.csv``;
case-insensitive) is one drive; the
vehicle is the name of the folder that holds it (``fleet/VAN-07/2026-11-02.blf`` belongs to
``VAN-07``).

Folders are searched through symbolic links (a vehicle folder linked from another disk is
searched like any other), each real folder once, so a link back up the tree (a loop) ends
the descent instead of repeating it; glob patterns are matched over the same walk, so a
``**`` over a tree with a loop finishes too. A link to a log that no longer exists is
kept: its drive fails with the reason (``No such file or directory``).
"""
from __future__ import annotations

import fnmatch
import glob
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Iterator

from estimator.fleet.drive import DRIVE_SUFFIXES
from suspid.can.logs import GZIP_READ
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
    suf = p.suffix.lower()
    if suf == ".gz":   # a compressed text log python-can reads (F.asc.gz)
        inner = Path(p.stem).suffix.lower()
        suf = inner if inner in GZIP_READ else suf
    return suf in DRIVE_SUFFIXES and not p.name.startswith(".")


def _entries(root: Path, descend: Callable[[tuple[str, ...]], bool] = lambda rel: True
             ) -> Iterator[tuple[Path, tuple[str, ...], bool]]:
    """Every entry below ``root`` (not ``root`` itself) as ``(path, parts relative to root,
    is_dir)``, in name order: hidden names skipped, symbolic links to folders followed, each
    real folder (device, inode) entered once, a folder entered only if ``descend(parts)``;
    unreadable folders skipped."""
    seen: set[tuple[int, int]] = set()

    def visit(d: Path, rel: tuple[str, ...]) -> Iterator[tuple[Path, tuple[str, ...], bool]]:
        try:
            st = d.stat()
            with os.scandir(d) as it:
                entries = sorted(it, key=lambda e: e.name)
        except OSError:
            return
        if (st.st_dev, st.st_ino) in seen:
            return
        seen.add((st.st_dev, st.st_ino))
        for e in entries:
            if e.name.startswith("."):
                continue
            try:
                is_dir = e.is_dir()
            except OSError:
                is_dir = False
            sub = rel + (e.name,)
            yield d / e.name, sub, is_dir
            if is_dir and descend(sub):
                yield from visit(d / e.name, sub)

    yield from visit(root, ())


def _match(parts: tuple[str, ...], pattern: tuple[str, ...]) -> bool:
    """Whether path components match pattern components (``**``: any number of them)."""
    if not pattern:
        return not parts
    if pattern[0] == "**":
        return any(_match(parts[i:], pattern[1:]) for i in range(len(parts) + 1))
    return (bool(parts) and fnmatch.fnmatchcase(parts[0], pattern[0])
            and _match(parts[1:], pattern[1:]))


def _glob(pattern: str) -> tuple[bool, list[Path]]:
    """Whether a glob pattern (``*``, ``?``, ``[...]``, ``**``) matches anything, and the
    files it names: those it matches and those in the folders it matches (one walk by
    :func:`_entries` below the pattern's literal leading folders)."""
    parts = Path(pattern).parts
    n = next((i for i, part in enumerate(parts) if glob.has_magic(part)), len(parts))
    root, rest = Path(*parts[:n]) if n else Path("."), parts[n:]
    if not root.is_dir():
        return False, []

    def matched(rel: tuple[str, ...]) -> bool:
        return any(_match(rel[:i], rest) for i in range(1, len(rel) + 1))

    def descend(rel: tuple[str, ...]) -> bool:
        return "**" in rest or len(rel) < len(rest) or matched(rel)

    hit, files = False, []
    for q, rel, is_dir in _entries(root, descend):
        if matched(rel):
            hit = True
            if not is_dir:
                files.append(q)
    return hit, files


def find_drives(inputs: Iterable[str]) -> list[DriveFile]:
    """Every drive log named by ``inputs``, sorted by path, each once.

    Parameters
    ----------
    inputs : iterable of str
        Directories (searched recursively through symbolic links, each real folder once;
        hidden files and folders skipped), glob
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
        for q, _, is_dir in _entries(d):
            # a link to a log that is gone (an unmounted share) is a drive that fails with
            # its reason, not a log silently left out
            if not is_dir and _is_drive(q) and (q.is_file() or q.is_symlink()):
                add(q)

    for item in inputs:
        p = Path(item)
        if p.is_dir():
            walk(p)
        elif p.is_file():
            add(p)
        elif glob.has_magic(item):
            hit, files = _glob(item)
            if not hit:
                raise InputError(f"--input {item}: the pattern matches no file")
            for q in files:
                if (q.is_file() or q.is_symlink()) and _is_drive(q):
                    add(q)
        else:
            raise InputError(f"--input {item}: no such file or directory")
    return sorted(found.values(), key=lambda d: d.path)
