"""CAN FD messages (payloads over 8 bytes) through the decoder's one path: the E2E CRC over
the whole payload, signals beyond byte 8 decoded, wrong lengths rejected, equal to the
frame-by-frame oracle live, in array batches and from a candump log."""
from __future__ import annotations

from pathlib import Path

import can
import cantools
import numpy as np
import pytest

from estimator.decode import DecodeListener, feed_log
from suspid.can.crc import e2e_protect
from suspid.can.logs import FrameArrays, read_log
from tests.can.frame_by_frame import frame_by_frame
from tests.can.test_batch_equivalence import _write_candump, snapshot

FD_DBC = """VERSION ""

NS_ :

BS_:

BU_: ECU

BO_ 544 WideBody: 16 ECU
 SG_ CRC : 0|8@1+ (1,0) [0|255] "-" ECU
 SG_ Counter : 8|4@1+ (1,0) [0|14] "-" ECU
 SG_ Disp : 16|16@1- (1e-05,0) [-0.32768|0.32767] "m" ECU
 SG_ Acc : 96|16@1- (0.001,0) [-32.768|32.767] "m/s2" ECU

BA_DEF_ BO_ "E2EProfile" STRING ;
BA_DEF_DEF_ "E2EProfile" "";
BA_ "E2EProfile" BO_ 544 "P01";
"""
MAP = ["x1=WideBody.Disp", "x1_ddot=WideBody.Acc"]
FS = 500.0


def _frames(db: cantools.database.can.Database, n: int) -> tuple[list[can.Message], np.ndarray]:
    """``n`` protected 16-byte frames at 500 Hz, then the faults: a lost frame, a bit flip in
    byte 12 (beyond the first 8), a 12-byte and an 8-byte frame under the same ID."""
    msg = db.get_message_by_name("WideBody")
    rng = np.random.default_rng(5)
    acc = np.round(rng.normal(0.0, 3.0, n), 3)
    out = []
    for k in range(n):
        data = bytearray(msg.encode({"CRC": 0, "Counter": 0, "Disp": round(0.001 * k % 0.3, 5),
                                     "Acc": float(acc[k])}))
        e2e_protect(data, 544, k)
        out.append(can.Message(timestamp=1.0 + k / FS, arbitration_id=544, is_fd=True,
                               is_extended_id=False, data=data, check=False))
    del out[40]                                    # lost: counted, the rest accepted
    out[100].data[12] ^= 0x10                       # the CRC covers byte 12: rejected
    t = out[200].timestamp
    out.insert(201, can.Message(timestamp=t, arbitration_id=544, is_fd=True,
                                is_extended_id=False, data=bytes(12), check=False))
    out.insert(202, can.Message(timestamp=t, arbitration_id=544, is_extended_id=False,
                                data=bytes(8), check=False))
    return out, acc


@pytest.fixture()
def dbc(tmp_path: Path) -> Path:
    path = tmp_path / "fd.dbc"
    path.write_text(FD_DBC)
    return path


def _listener(dbc: Path, **kw: object) -> DecodeListener:
    return DecodeListener("quarter2", dbc, MAP, capacity=1 << 12, **kw)  # type: ignore[arg-type]


def test_fd_frames_decode_beyond_byte_eight_as_the_oracle(dbc: Path, tmp_path: Path) -> None:
    db = cantools.database.load_file(str(dbc))
    frames, acc = _frames(db, 300)
    ref = frame_by_frame(_listener(dbc, batch_size=1))
    for m in frames:
        ref.on_message_received(m)
    live = _listener(dbc, batch_size=7)
    for m in frames:
        live.on_message_received(m)
    arrays = _listener(dbc)
    arrays.feed_arrays(FrameArrays.from_messages(frames))
    want = snapshot(ref)
    for lst in (live, arrays):
        assert snapshot(lst) == want
    log = tmp_path / "fd.log"    # times to the µs: against the oracle fed the log's frames
    _write_candump(log, frames)
    logged, ref_log = _listener(dbc), frame_by_frame(_listener(dbc, batch_size=1))
    feed_log(logged, log)
    for m in read_log(log):
        ref_log.on_message_received(m)
    assert snapshot(logged) == snapshot(ref_log)
    assert logged.frame_stats() == arrays.frame_stats()
    stats = arrays.frame_stats()
    assert stats["rejected"]["crc"] == 1 and stats["rejected"]["dlc"] == 2
    assert stats["accepted"] == 298 and stats["lost"] == 2   # frame 40 and the bad-CRC 100
    t, v = arrays.buffer.sources["WideBody"].snapshot()
    keep = np.setdiff1d(np.arange(300), [40, 101])   # 100 after the deletion is sample 101
    np.testing.assert_allclose(v[:, 1], acc[keep], atol=1e-9)
    np.testing.assert_allclose(t, 1.0 + keep / FS)
