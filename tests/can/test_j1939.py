"""J1939: 29-bit frames matched to a J1939 DBC by PGN, whatever their source address (and, for
a PDU1 group, their destination); one sender per parameter group decoded."""
from __future__ import annotations

import json
from pathlib import Path

import can
import cantools
import numpy as np
import pytest
from cantools.j1939 import frame_id_pack

from estimator.decode import load_log_as_measurement
from estimator.decode.j1939 import J1939Match, parse_source
from estimator.decode.listener import DecodeListener
from suspid.can.dbc import load_dbc
from suspid.can.logs import open_log_writer, read_log
from suspid.cli import main
from suspid.errors import InputError, UsageError

from tests.can.conftest import REALDATA
from tests.conftest import write_config

J1939_DIR = REALDATA / "j1939-small"
LOG = J1939_DIR / "FCBF0606_00003482_00000001-60B621D9.MF4"
DBC = J1939_DIR / "CSS-Electronics-SAE-J1939-DEMO.dbc"

#: a J1939 DBC of one PDU1 group (PGN 0xEF00, proprietary A: PF 239 < 240, so the PS byte is
#: a destination address) and one PDU2 group (PGN 0xFF10), listed with source address 0xFE
PDU_DBC = """VERSION ""
NS_ :
BS_:
BU_:
BO_ 2364473598 PropA: 8 Vector__XXX
 SG_ Height : 0|16@1- (0.001,0) [-32|32] "m" Vector__XXX
BO_ 2566852862 PropB: 8 Vector__XXX
 SG_ Level : 0|16@1- (0.001,0) [-32|32] "m" Vector__XXX
BA_DEF_ "ProtocolType" STRING ;
BA_DEF_DEF_ "ProtocolType" "";
BA_ "ProtocolType" "J1939";
"""


def _realdata() -> None:
    if not LOG.is_file():
        pytest.skip(f"real recording not found: {LOG}")


def _cantools_values(message: str, signal: str) -> tuple[np.ndarray, np.ndarray]:
    """Times and values of every frame of the message's PGN, decoded by cantools itself."""
    db = cantools.database.load_file(str(DBC))
    msg = db.get_message_by_name(message)
    pgn = cantools.j1939.pgn_from_frame_id(msg.frame_id)
    rows = [(m.timestamp, msg.decode(m.data)[signal]) for m in read_log(LOG)
            if m.is_extended_id and cantools.j1939.pgn_from_frame_id(m.arbitration_id) == pgn]
    arr = np.array(rows, dtype=float)
    return arr[:, 0], arr[:, 1]


def test_canedge_session_decodes_ccvs1_speed_with_the_published_dbc() -> None:
    """The DBC lists CCVS1 as 0x18FEF1FE (source 0xFE); the truck's frames come from 0x47.
    (The truck stands still in this session: every speed is 0 km/h, as cantools decodes it.)"""
    _realdata()
    meas, frames = load_log_as_measurement(
        LOG, "quarter1", DBC, ["x_dot=CCVS1.WheelBasedVehicleSpeed*0.2777777777777778"])
    assert frames["accepted"] == 184
    j = frames["j1939"]
    assert j["messages"]["CCVS1"] == {"pgn": 65265, "source": "0x47", "sources": {"0x47": 184}}
    assert j["messages"]["EEC1"]["sources"] == {"0x00": 577}
    assert frames["ignored"] == 577   # EEC1: in the DBC, not mapped
    _t, want = _cantools_values("CCVS1", "WheelBasedVehicleSpeed")
    x = meas.measured["x_dot"]
    got = x[~np.isnan(x)]
    assert got.size == 184   # every frame on its own cell of the 1 s grid (3 cells empty)
    np.testing.assert_array_equal(np.unique(got), np.unique(want / 3.6))
    assert not any("J1939" in w for w in meas.warnings)   # one sender per PGN


def test_canedge_session_engine_speed_equals_cantools() -> None:
    """EEC1 (PGN 61444, PDU2 with PS 4) from the engine (0x00), listed as 0x0CF004FE: every
    value as cantools decodes the frame."""
    _realdata()
    meas, frames = load_log_as_measurement(LOG, "quarter1", DBC, ["x=EEC1.EngineSpeed"],
                                           arrival_slots=False, dt=None)
    assert frames["accepted"] == 577
    assert frames["j1939"]["messages"]["EEC1"]["source"] == "0x00"
    _t, want = _cantools_values("EEC1", "EngineSpeed")
    got = meas.measured["x"]
    got = got[~np.isnan(got)]
    # every frame of this session carries the same payload (engine and vehicle at rest)
    assert want.size == 577 and set(got.tolist()) == set(want.tolist())
    assert got.size >= 0.95 * want.size


def test_no_matching_source_names_the_senders_and_the_logs_pgns() -> None:
    _realdata()
    with pytest.raises(InputError) as ei:
        load_log_as_measurement(LOG, "quarter1", DBC, ["x_dot=CCVS1.WheelBasedVehicleSpeed"],
                                j1939_source="0x00")
    msg = str(ei.value)
    assert "\n" not in msg
    assert "CCVS1 (PGN 65265) is sent by 0x47 (184 frames), not by can.j1939_source 0x00" in msg
    assert "PGNs in the log of 16: 61444 (EEC1, 577 frames), " in msg


def test_identify_cli_source_filter_and_bad_address(capsys: pytest.CaptureFixture[str],
                                                    tmp_path: Path) -> None:
    _realdata()
    base = ["identify", "--model", "quarter1", "--input", str(LOG), "--dbc", str(DBC),
            "--map", "x=EEC1.EngineSpeed*0.001", "--json"]
    good = write_config(tmp_path, '[can]\nj1939_source = "0x00"\n', "good.toml")
    assert main(base + ["--config", good]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["frames"]["accepted"] == 577
    assert res["frames"]["j1939"]["messages"]["EEC1"]["source"] == "0x00"
    bad = write_config(tmp_path, "[can]\nj1939_source = 300\n", "bad.toml")
    assert main(base + ["--config", bad]) == 2
    err = capsys.readouterr().err
    assert err == (f"error: {bad}: can.j1939_source: expected an address (string or integer) "
                   ">= 0 and <= 253, got 300 (integer)\n")


def _pdu_log(path: Path, senders: dict[int, float], dest: int = 0x21) -> None:
    """PropA (PDU1, to ``dest``) and PropB (PDU2) from each source address in ``senders``
    (value: its height offset), 200 frames each at 100 Hz, interleaved, priority 6 and 3."""
    with open_log_writer(path) as w:
        for i in range(200):
            t = 1.0 + 0.01 * i
            for sa, off in senders.items():
                h = int(round((off + 0.01 * np.sin(0.3 * i)) / 0.001))
                data = h.to_bytes(2, "little", signed=True) + bytes(6)
                w.on_message_received(can.Message(
                    timestamp=t, is_extended_id=True, data=data,
                    arbitration_id=frame_id_pack(6, 0, 0, 0xEF, dest, sa)))
                w.on_message_received(can.Message(
                    timestamp=t, is_extended_id=True, data=data,
                    arbitration_id=frame_id_pack(3, 0, 0, 0xFF, 0x10, sa)))


@pytest.fixture
def pdu_dbc(tmp_path: Path) -> Path:
    p = tmp_path / "pdu.dbc"
    p.write_text(PDU_DBC)
    return p


def test_pdu1_destination_and_priority_are_no_part_of_the_pgn(tmp_path: Path,
                                                              pdu_dbc: Path) -> None:
    log = tmp_path / "pdu.log"
    _pdu_log(log, {0x03: 0.1}, dest=0x21)
    meas, frames = load_log_as_measurement(log, "quarter2", pdu_dbc,
                                           ["x1=PropA.Height", "x2=PropB.Level"])
    assert frames["accepted"] == 400 and frames["rejected"]["unknown_id"] == 0
    m = frames["j1939"]["messages"]
    assert m["PropA"] == {"pgn": 0xEF00, "source": "0x03", "sources": {"0x03": 200}}
    assert m["PropB"]["pgn"] == 0xFF10
    np.testing.assert_allclose(meas.measured["x1"], meas.measured["x2"])
    assert abs(np.nanmean(meas.measured["x1"]) - 0.1) < 0.01


def test_several_senders_first_one_decoded_with_a_warning_or_the_one_chosen(
        tmp_path: Path, pdu_dbc: Path) -> None:
    log = tmp_path / "two.log"
    _pdu_log(log, {0x03: 0.1, 0x0B: -0.2})
    maps = ["x1=PropA.Height"]
    meas, frames = load_log_as_measurement(log, "quarter2", pdu_dbc, maps)
    assert frames["accepted"] == 200 and frames["j1939"]["other_source"] == 200 + 200
    assert frames["j1939"]["messages"]["PropA"]["source"] == "0x03"
    assert abs(np.nanmean(meas.measured["x1"]) - 0.1) < 0.01   # never the two mixed
    warn = [w for w in meas.warnings if "J1939" in w]
    assert warn == [f"{log}: J1939 PropA (PGN 61184) is sent by 2 sources, 0x03 (200 frames), "
                    "0x0b (200 frames); decoded 0x03 (the first), the others not; choose one "
                    "with the --config file's can.j1939_source"]
    meas, frames = load_log_as_measurement(log, "quarter2", pdu_dbc, maps, j1939_source="11")
    assert abs(np.nanmean(meas.measured["x1"]) + 0.2) < 0.01
    assert frames["j1939"]["messages"]["PropA"]["source"] == "0x0b"
    assert not any("J1939" in w for w in meas.warnings)


def test_live_frames_match_like_the_log(tmp_path: Path, pdu_dbc: Path) -> None:
    """Frame by frame (a live bus) and as arrays (a log): the same samples."""
    log = tmp_path / "two.log"
    _pdu_log(log, {0x03: 0.1, 0x0B: -0.2})
    db = load_dbc(pdu_dbc)
    live = DecodeListener("quarter2", db, ["x1=PropA.Height"], batch_size=1,
                          j1939_source="0x0b")
    for msg in read_log(log):
        live.on_message_received(msg)
    whole, frames = load_log_as_measurement(log, "quarter2", db, ["x1=PropA.Height"],
                                            j1939_source="0x0b", arrival_slots=False)
    got = live.aligned()
    np.testing.assert_array_equal(got.values["x1"], whole.measured["x1"])
    assert live.frame_stats()["j1939"] == frames["j1939"]


def test_source_address_parsing_and_a_dbc_without_j1939() -> None:
    assert parse_source("0x00") == 0 and parse_source(" 71 ") == 71 and parse_source(None) is None
    for bad in ("0xFE", "-1", "engine"):
        with pytest.raises(UsageError):
            parse_source(bad)
    assert J1939Match.from_db(load_dbc()) is None
    with pytest.raises(UsageError) as ei:
        J1939Match.from_db(load_dbc(), "0x00")
    assert "has no J1939 message" in str(ei.value)
