"""Finding the drive logs of a fleet: directories (recursive, through links, each real folder
once), glob patterns and files; a log's vehicle is the name of its folder.
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
    """A drive log found on disk: ``path`` as found, ``vehicle`` the name of its folder."""

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
    """Every entry below ``root`` as ``(path, parts, is_dir)`` in name order: hidden names skipped,
    each real folder entered once and only if ``descend(parts)``.
    """
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
    """Whether a glob pattern matches anything, and the files it or its matched folders name."""
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
    """Every drive log named by ``inputs`` (directories, glob patterns or files), sorted, each once.

    An explicitly named file is taken whatever its suffix. InputError for an input that is
    neither an existing path nor a pattern matching anything.
    """
    found: dict[str, DriveFile] = {}

    def add(p: Path) -> None:
        if str(p) not in found:
            found[str(p)] = DriveFile(str(p), vehicle_of(p))

    for item in inputs:
        p = Path(item)
        if p.is_dir():
            for q, _, is_dir in _entries(p):
                if not is_dir and _is_drive(q) and (q.is_file() or q.is_symlink()):
                    add(q)
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
