"""Finding drive logs (folders, patterns, files) and the per-worker DBC cache."""
from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from estimator.fleet.discover import find_drives, vehicle_of
from estimator.fleet.drive import cached_database
from suspid.can.dbc import default_dbc_path
from suspid.errors import InputError


def test_folders_patterns_and_files(tmp_path: Path) -> None:
    for rel in ("A/d1.log", "A/d2.BLF", "A/sub/B2/x.mf4", "B/x.csv", "B/readme.txt",
                ".hidden/V/z.log", "A/.tmp.log", "C/y.asc", "C/z.trc"):
        p = tmp_path / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text("x")
    found = find_drives([str(tmp_path)])
    rel = [(str(Path(d.path).relative_to(tmp_path)), d.vehicle) for d in found]
    assert rel == [("A/d1.log", "A"), ("A/d2.BLF", "A"), ("A/sub/B2/x.mf4", "B2"),
                   ("B/x.csv", "B"), ("C/y.asc", "C"), ("C/z.trc", "C")]
    pat = find_drives([str(tmp_path / "*" / "*.log"), str(tmp_path / "C"),
                       str(tmp_path / "A" / "d1.log")])           # overlaps counted once
    assert [Path(d.path).name for d in pat] == ["d1.log", "y.asc", "z.trc"]
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
