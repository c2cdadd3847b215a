"""A gzip-compressed ASC or TRC log (``F.asc.gz``) is read as python-can's LogReader reads
it; a writer still writes plain files only."""
from __future__ import annotations

import gzip
import json
import shutil
from pathlib import Path

import pytest

from suspid.can.logs import ReadStats, is_can_log, log_format, read_log
from suspid.cli import main
from suspid.errors import InputError, UsageError


@pytest.fixture(scope="module")
def asc(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("gz")
    csv = d / "b.csv"
    assert main(["simulate", "--model", "quarter2", "--scenario", "bump", "--duration", "1",
                 "--fs", "200", "--out", str(csv)]) == 0
    out = d / "b.asc"
    assert main(["encode", "--input", str(csv), "--out", str(out)]) == 0
    return out


def _gz(src: Path, dst: Path) -> Path:
    with open(src, "rb") as fi, gzip.open(dst, "wb") as fo:
        shutil.copyfileobj(fi, fo)
    return dst


def test_asc_gz_reads_the_frames_of_the_asc(asc: Path, tmp_path: Path) -> None:
    """(was: `unknown CAN log format '.gz'`, exit 2)"""
    gz = _gz(asc, tmp_path / "b.asc.gz")
    assert is_can_log(gz) and log_format(gz) == ".asc"
    plain = [(m.timestamp, m.arbitration_id, bytes(m.data)) for m in read_log(asc)]
    packed = [(m.timestamp, m.arbitration_id, bytes(m.data)) for m in read_log(gz)]
    assert packed == plain and len(plain) > 100


def test_identify_and_monitor_read_asc_gz(asc: Path, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    gz = _gz(asc, tmp_path / "b.ASC.GZ")
    args = ["identify", "--model", "quarter2", "--fix", "m1=300", "--json", "--input"]
    assert main(args + [str(asc)]) == 0
    a = json.loads(capsys.readouterr().out)
    assert main(args + [str(gz)]) == 0
    b = json.loads(capsys.readouterr().out)
    assert b["params"] == a["params"] and b["frames"] == a["frames"]
    assert main(["monitor", "--model", "quarter2", "--fix", "m1=300", "--window", "0.5",
                 "--step", "0.5", "--jsonl", "--input", str(gz)]) == 0
    summary = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert summary["frames"]["accepted"] == a["frames"]["accepted"]


def test_a_damaged_gz_keeps_its_frames_and_writers_refuse_gz(asc: Path, tmp_path: Path) -> None:
    """A .gz cut short keeps the frames before the cut and names the damage (nothing valid
    is lost); a file that is no gzip at all, or cut before its first frame, is one error."""
    whole = _gz(asc, tmp_path / "whole.asc.gz").read_bytes()
    plain = [(m.timestamp, m.arbitration_id, bytes(m.data)) for m in read_log(asc)]
    cut = tmp_path / "cut.asc.gz"
    cut.write_bytes(whole[:int(0.6 * len(whole))])
    stats = ReadStats()
    kept = [(m.timestamp, m.arbitration_id, bytes(m.data)) for m in read_log(cut, stats)]
    assert 0 < len(kept) < len(plain) and kept == plain[:len(kept)]
    assert stats.truncated and stats.malformed == 1
    assert stats.damage.startswith(f"{cut}: damaged ASC file: the compressed stream ends after "
                                   "line ") and f"{len(kept)} frames read before it" in stats.damage
    head = tmp_path / "head.asc.gz"
    head.write_bytes(whole[:40])
    with pytest.raises(InputError, match=r"head.asc.gz: not a readable gzip file after line \d+"):
        list(read_log(head))
    fake = tmp_path / "fake.asc.gz"
    fake.write_bytes(asc.read_bytes())
    with pytest.raises(InputError, match="fake.asc.gz: not a readable gzip file"):
        list(read_log(fake))
    with pytest.raises(UsageError, match="unknown output log format '.gz'"):
        log_format(tmp_path / "x.asc.gz", "output log", compressed=False)
    assert not is_can_log(tmp_path / "x.blf.gz") and not is_can_log(tmp_path / "x.csv.gz")
