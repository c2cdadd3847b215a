"""Binary logs cut short (a logger losing power, an upload stopped early): the frames before
the damage are kept, the damage is named in one line (file, byte) and counted ``malformed``,
and no library traceback or destructor noise reaches the terminal."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from estimator.decode import load_log_as_measurement
from suspid.can.logs import ReadStats, read_log
from suspid.cli import main

from tests.can.conftest import REALDATA

REPO = Path(__file__).parents[2]
CANEDGE_J1939 = REALDATA / "j1939-small" / "FCBF0606_00003482_00000001-60B621D9.MF4"


def _cut(src: Path, dst: Path, fraction: float) -> Path:
    data = src.read_bytes()
    dst.write_bytes(data[:int(len(data) * fraction)])
    return dst


@pytest.fixture(scope="module")
def q2_mf4(q2_csv: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("mf4") / "q2.mf4"
    assert main(["encode", "--input", str(q2_csv), "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def q2_blf(q2_csv: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("blf") / "q2.blf"
    assert main(["encode", "--input", str(q2_csv), "--out", str(out)]) == 0
    return out


@pytest.mark.parametrize("fraction", [0.96, 0.6, 0.3, 0.05])
def test_mf4_written_by_python_can_cut_anywhere_is_one_error_line(
        q2_mf4: Path, tmp_path: Path, fraction: float, capsys: pytest.CaptureFixture[str]) -> None:
    """python-can's MF4Writer (asammdf) writes the data first and the channel groups at the
    end: a cut anywhere loses the record layout, so no frame can be read; the error names
    the block beyond the end of the file."""
    cut = _cut(q2_mf4, tmp_path / "cut.mf4", fraction)
    assert main(["identify", "--model", "quarter2", "--input", str(cut), "--json"]) == 2
    out = capsys.readouterr()
    assert out.out == ""
    assert out.err.count("\n") == 1 and out.err.startswith(f"error: {cut}: damaged MF4 file: ")
    assert "beyond the end of the file" in out.err and "no frame can be read" in out.err
    assert "Traceback" not in out.err and "Exception ignored" not in out.err


def test_cut_mf4_in_a_fresh_process_prints_no_destructor_noise(q2_mf4: Path,
                                                               tmp_path: Path) -> None:
    """asammdf's ``MDF4.__del__`` on a file it could not open raised ``AttributeError: _file``
    and Python printed 8 lines of "Exception ignored in" after the error line."""
    cut = _cut(q2_mf4, tmp_path / "cut96.mf4", 0.96)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.run([sys.executable, "-m", "suspid", "identify", "--model", "quarter2",
                           "--input", str(cut), "--json"], capture_output=True, text=True,
                          env=env, timeout=120, check=False)
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert proc.stderr.count("\n") == 1, proc.stderr
    assert "damaged MF4 file" in proc.stderr and "byte" in proc.stderr
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr


@pytest.mark.parametrize("fraction,kept", [(0.96, 1734), (0.6, 1000), (0.2, 0)])
def test_canedge_mf4_cut_keeps_the_frames_before_the_cut(tmp_path: Path, fraction: float,
                                                         kept: int) -> None:
    """A CANedge writes its channel groups first and appends records: a cut inside the
    records keeps the whole ones asammdf reads (it reads them 1000 at a time and gives up on
    the chunk that holds the cut) and names the record cut short."""
    if not CANEDGE_J1939.is_file():
        pytest.skip(f"real recording not found: {CANEDGE_J1939}")
    cut = _cut(CANEDGE_J1939, tmp_path / "cut.MF4", fraction)
    stats = ReadStats()
    frames = list(read_log(cut, stats))
    assert len(frames) == stats.frames == kept
    assert stats.truncated and stats.malformed == 1
    assert stats.damage.startswith(f"{cut}: damaged MF4 file: the file ends inside a record at "
                                   "byte ")
    assert f"{kept} frames read before it are used" in stats.damage
    whole = ReadStats()
    assert sum(1 for _ in read_log(CANEDGE_J1939, whole)) == 1815
    assert whole.damage == "" and whole.malformed == 0 and not whole.truncated


def test_canedge_mf4_cut_in_its_header_blocks_names_the_block(tmp_path: Path) -> None:
    if not CANEDGE_J1939.is_file():
        pytest.skip(f"real recording not found: {CANEDGE_J1939}")
    cut = _cut(CANEDGE_J1939, tmp_path / "cut.MF4", 0.09)
    with pytest.raises(Exception) as ei:
        list(read_log(cut))
    msg = str(ei.value)
    assert msg.startswith(f"{cut}: damaged MF4 file: the block at byte 7456 (linked from the DG "
                          "block at byte 4040) is beyond the end of the file (6553 bytes)")


@pytest.mark.parametrize("fraction", [0.6, 0.96, 0.3])
def test_cut_blf_keeps_its_frames_and_names_the_truncation(
        q2_blf: Path, tmp_path: Path, fraction: float) -> None:
    cut = _cut(q2_blf, tmp_path / "cut.blf", fraction)
    stats = ReadStats()
    n = sum(1 for _ in read_log(cut, stats))
    assert 0 < n < sum(1 for _ in read_log(q2_blf))
    assert stats.truncated and stats.malformed == 1
    assert stats.damage.startswith(f"{cut}: damaged BLF file: the object at byte ")
    assert f"the header announces {q2_blf.stat().st_size} bytes" in stats.damage
    meas, frames = load_log_as_measurement(cut, "quarter2")
    assert frames["rejected"]["malformed"] == 1
    assert stats.damage in meas.warnings
    whole = ReadStats()
    list(read_log(q2_blf, whole))
    assert whole.damage == "" and not whole.truncated


def test_cut_blf_identify_exit_0_with_the_warning(q2_blf: Path, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    cut = _cut(q2_blf, tmp_path / "cut.blf", 0.6)
    rc = main(["identify", "--model", "quarter2", "--input", str(cut), "--fix", "m1=250",
               "--json"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    res = json.loads(out.out)
    assert res["frames"]["rejected"]["malformed"] == 1
    assert any(w.startswith(f"{cut}: damaged BLF file: the object at byte ")
               for w in res["warnings"])
    assert "Traceback" not in out.err
