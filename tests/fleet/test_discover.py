"""Finding drive logs (folders, patterns, files) and the per-worker DBC cache."""
from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from estimator.fleet.discover import find_drives, vehicle_of
from estimator.fleet.drive import IdentifySettings, cached_database, identify_drive
from suspid.can.dbc import default_dbc_path
from suspid.errors import InputError


def test_folders_patterns_and_files(tmp_path: Path) -> None:
    for rel in ("A/d1.log", "A/d2.BLF", "A/sub/B2/x.mf4", "B/x.csv", "B/readme.txt",
                ".hidden/V/z.log", "A/.tmp.log", "C/y.asc", "C/z.trc", "C/w.asc.gz",
                "C/v.log.gz", "C/u.gz"):
        p = tmp_path / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text("x")
    found = find_drives([str(tmp_path)])
    rel = [(str(Path(d.path).relative_to(tmp_path)), d.vehicle) for d in found]
    assert rel == [("A/d1.log", "A"), ("A/d2.BLF", "A"), ("A/sub/B2/x.mf4", "B2"),
                   ("B/x.csv", "B"), ("C/w.asc.gz", "C"), ("C/y.asc", "C"), ("C/z.trc", "C")]
    pat = find_drives([str(tmp_path / "*" / "*.log"), str(tmp_path / "C"),
                       str(tmp_path / "A" / "d1.log")])           # overlaps counted once
    assert [Path(d.path).name for d in pat] == ["d1.log", "w.asc.gz", "y.asc", "z.trc"]
    assert vehicle_of("VAN-9/drive.blf") == "VAN-9"
    with pytest.raises(InputError, match="no such file"):
        find_drives([str(tmp_path / "missing")])
    with pytest.raises(InputError, match="matches no file"):
        find_drives([str(tmp_path / "*.nothing")])


def test_dbc_parsed_once_per_file_version(tmp_path: Path) -> None:
    dbc = tmp_path / "s.dbc"
    shutil.copy(default_dbc_path(), dbc)
    a, b = cached_database(str(dbc)), cached_database(str(dbc))
    assert a is b
    st = dbc.stat()
    os.utime(dbc, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))   # edited: parsed again
    c = cached_database(str(dbc))
    assert c is not a and len(c.messages) == len(a.messages)
    assert cached_database(None) is cached_database(None)
    with pytest.raises(InputError, match="no such DBC"):
        cached_database(str(tmp_path / "missing.dbc"))


def test_symlinked_folders_followed_and_loops_end(tmp_path: Path) -> None:
    """A vehicle folder linked from another disk is searched; links back up the tree (two
    loops: 2^40 paths for a walk that follows them blindly) end the descent, for folders
    and ``**`` patterns alike."""
    fleet, disk2 = tmp_path / "fleet", tmp_path / "disk2"
    for rel in ("disk2/VAN-L/a.csv", "fleet/VAN-R/b.asc", "fleet/VAN-R/deep/er/c.log"):
        p = tmp_path / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text("x")
    (fleet / "VAN-L").symlink_to(disk2 / "VAN-L", target_is_directory=True)
    (fleet / "VAN-R" / "loop").symlink_to(fleet, target_is_directory=True)
    (fleet / "VAN-R" / "deep" / "up").symlink_to(tmp_path, target_is_directory=True)
    expected = [("VAN-L/a.csv", "VAN-L"), ("VAN-R/b.asc", "VAN-R"), ("VAN-R/deep/er/c.log", "er")]
    for inputs in ([str(fleet)], [str(fleet / "**" / "*.*")], [str(fleet / "**")],
                   [str(fleet / "VAN-*")]):
        found = find_drives(inputs)
        assert [(str(Path(d.path).relative_to(fleet)), d.vehicle) for d in found] == expected
    assert [Path(d.path).name for d in find_drives([str(fleet / "*" / "*.csv")])] == ["a.csv"]
    assert [Path(d.path).name for d in find_drives([str(fleet / "**" / "c.log")])] == ["c.log"]


def test_link_to_a_missing_log_is_a_failed_drive(tmp_path: Path) -> None:
    """A log linked from a share that is not mounted is a failed drive naming the path, not
    a log silently left out."""
    (tmp_path / "VAN-M").mkdir()
    link = tmp_path / "VAN-M" / "d.blf"
    link.symlink_to(tmp_path / "unmounted" / "d.blf")
    (tmp_path / "VAN-M" / "self.log").symlink_to(tmp_path / "VAN-M" / "self.log")
    for inputs in ([str(tmp_path)], [str(tmp_path / "*" / "*.*")]):
        assert [Path(d.path).name for d in find_drives(inputs)] == ["d.blf", "self.log"]
    rec = identify_drive(str(link), "VAN-M", IdentifySettings(model="quarter2"))
    assert rec["status"] == "failed" and rec["error"].startswith(str(link))
    assert "No such file or directory" in rec["error"] and "\n" not in rec["error"]
