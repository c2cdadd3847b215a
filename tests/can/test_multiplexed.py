"""Multiplexed signals of a user's DBC: each mapped signal read from the frames of its pages only.

The logs are built the way a user's logger writes them: a simulated quarter-car record, its
samples encoded by cantools into the frames of a multiplexed message (the pages in turn,
one frame per sample) and written by python-can's own log writers.
"""
from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path
from typing import Any

import can
import cantools
import numpy as np
import pytest

from estimator.decode import DecodeListener, feed_log, load_log_as_measurement
from estimator.decode.pages import PageSplit
from suspid.can.logs import read_log
from suspid.cli import main
from suspid.errors import InputError
from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement, read_measurement
from suspid.models import get_model
from suspid.simulate import simulate

from tests.can.frame_by_frame import frame_by_frame
from tests.can.test_batch_equivalence import snapshot

T0 = 1764183653.0
#: one Intel 16-bit field that every page lays out differently; Road in every frame
MUX_DBC = """VERSION ""

NS_ :

BS_:

BU_: ECU

BO_ 512 Chassis: 8 ECU
 SG_ Page M : 0|8@1+ (1,0) [0|255] "" ECU
 SG_ Height m0 : 8|16@1- (1e-05,0) [-0.32768|0.32767] "m" ECU
 SG_ Wheel m1 : 8|16@1- (1e-05,0) [-0.32768|0.32767] "m" ECU
 SG_ Temp m2 : 8|16@1- (0.1,-40) [-40|200] "degC" ECU
 SG_ Road : 39|16@0- (1e-05,0) [-0.32768|0.32767] "m" ECU
"""
#: the same signals, each in every frame
PLAIN_DBC = """VERSION ""

NS_ :

BS_:

BU_: ECU

BO_ 513 Plain: 8 ECU
 SG_ Height : 8|16@1- (1e-05,0) [-0.32768|0.32767] "m" ECU
 SG_ Wheel : 24|16@1- (1e-05,0) [-0.32768|0.32767] "m" ECU
 SG_ Road : 55|16@0- (1e-05,0) [-0.32768|0.32767] "m" ECU
"""
MUX_MAP = ["x1=Chassis.Height", "x2=Chassis.Wheel", "r=Chassis.Road"]
PLAIN_MAP = ["x1=Plain.Height", "x2=Plain.Wheel", "r=Plain.Road"]
FIX = ["--fix", "m1=300", "--fix", "m2=40"]


def _dbc(tmp_path: Path, text: str, name: str) -> tuple[Path, Any]:
    path = tmp_path / name
    path.write_text(text)
    return path, cantools.database.load_file(str(path))


def _q5(x: float) -> float:
    return round(float(x), 5)


def _write(path: Path, frames: list[can.Message]) -> Path:
    """``frames`` through python-can's writer of the suffix (candump -L, BLF, ASC)."""
    with can.Logger(str(path)) as w:
        for f in frames:
            w.on_message_received(f)
    return path


def mux_frames(db: Any, ref: Measurement, pages: list[int]) -> list[can.Message]:
    """One frame per sample of ``ref``: page ``pages[i % len(pages)]`` carries sample ``i``
    (page 0 the body position, 1 the wheel position, 2 a temperature, any other value
    nothing), the road in every frame."""
    msg = db.get_message_by_name("Chassis")
    out = []
    for i, t in enumerate(ref.t):
        page = pages[i % len(pages)]
        sig = ({"Height": _q5(ref.measured["x1"][i])} if page == 0 else
               {"Wheel": _q5(ref.measured["x2"][i])} if page == 1 else
               {"Temp": 25.0} if page == 2 else {})
        if sig:
            data = msg.encode({"Page": page, "Road": _q5(ref.road["r"][i]), **sig})
        else:   # a page the DBC does not define: cantools cannot encode it
            data = bytearray(msg.encode({"Page": 0, "Road": _q5(ref.road["r"][i]),
                                         "Height": 0.0}))
            data[0] = page
        out.append(can.Message(timestamp=T0 + float(t), arbitration_id=msg.frame_id,
                               is_extended_id=False, data=bytes(data)))
    return out


def plain_frames(db: Any, ref: Measurement) -> list[can.Message]:
    msg = db.get_message_by_name("Plain")
    return [can.Message(timestamp=T0 + float(t), arbitration_id=msg.frame_id,
                        is_extended_id=False,
                        data=msg.encode({"Height": _q5(ref.measured["x1"][i]),
                                         "Wheel": _q5(ref.measured["x2"][i]),
                                         "Road": _q5(ref.road["r"][i])}))
            for i, t in enumerate(ref.t)]


@pytest.fixture(scope="module")
def ref(q2_csv: Path) -> Measurement:
    return read_measurement(q2_csv, get_model("quarter2"))


def _identify(args: list[str]) -> dict[str, Any]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["identify", "--model", "quarter2", *args, *FIX, "--json"]) == 0
    return json.loads(out.getvalue())


def _rel(got: dict[str, float], true: dict[str, float]) -> float:
    return max(abs(got[k] - true[k]) / abs(true[k]) for k in true)


@pytest.mark.parametrize("suffix", [".log", ".blf"])
def test_pages_identify_as_well_as_plain_signals(ref: Measurement, tmp_path: Path,
                                                 suffix: str) -> None:
    mdbc, mdb = _dbc(tmp_path, MUX_DBC, "mux.dbc")
    pdbc, pdb = _dbc(tmp_path, PLAIN_DBC, "plain.dbc")
    mlog = _write(tmp_path / f"mux{suffix}", mux_frames(mdb, ref, [0, 1]))
    plog = _write(tmp_path / f"plain{suffix}", plain_frames(pdb, ref))
    mux = _identify(["--input", str(mlog), "--dbc", str(mdbc),
                     *[x for m in MUX_MAP for x in ("--map", m)]])
    plain = _identify(["--input", str(plog), "--dbc", str(pdbc),
                       *[x for m in PLAIN_MAP for x in ("--map", m)]])
    true = get_model("quarter2").defaults()
    # every frame accepted, no gap reported: the pages alternate, each fills every other
    # cell of the message's 2 ms grid
    assert mux["frames"]["accepted"] == ref.t.size
    assert sum(mux["frames"]["rejected"].values()) == 0
    assert not any("missing" in w for w in mux["warnings"]), mux["warnings"]
    assert _rel(plain["params"], true) < 0.005
    assert _rel(mux["params"], true) < 0.005
    assert _rel(mux["params"], plain["params"]) < 0.005


@pytest.mark.parametrize("suffix", [".log", ".asc"])
def test_each_signal_from_its_own_pages_only(ref: Measurement, tmp_path: Path,
                                             suffix: str) -> None:
    dbc, db = _dbc(tmp_path, MUX_DBC, "mux.dbc")
    # the pages in turn: body, wheel, temperature, and 7, a page the DBC does not have
    pages = [0, 1, 2, 7]
    log = _write(tmp_path / f"mux{suffix}", mux_frames(db, ref, pages))
    meas, stats = load_log_as_measurement(log, "quarter2", dbc,
                                          [*MUX_MAP, "x1_dot=Chassis.Page"])
    n = ref.t.size
    k = np.arange(n)
    page_of = np.array(pages)[k % 4]
    n7 = int(np.count_nonzero(page_of == 7))
    # the other pages are no error, and the unknown page is counted, not decoded
    assert stats["accepted"] == n and stats["ignored"] == 0
    assert sum(stats["rejected"].values()) == 0                    # type: ignore[attr-defined]
    assert stats["unknown_page"] == {"Chassis": n7} and n7 > 200
    assert any(f"{n7} frames of Chassis carry a multiplexer value that is no page" in w
               for w in meas.warnings), meas.warnings
    # one grid cell per frame (the message's 2 ms), not per page cycle (8 ms)
    assert meas.t.size == n
    np.testing.assert_allclose(meas.t - T0, ref.t, atol=1e-5)
    for ch, page in (("x1", 0), ("x2", 1)):
        v = meas.measured[ch]
        assert np.array_equal(~np.isnan(v), k % 4 == page), ch
        assert np.max(np.abs(v[k % 4 == page] - ref.measured[ch][k % 4 == page])) <= 5e-6 + 1e-12
    # the multiplexer and the signal of every frame, read from every frame
    np.testing.assert_array_equal(meas.measured["x1_dot"], page_of.astype(float))
    assert np.max(np.abs(meas.road["r"] - ref.road["r"])) <= 5e-6 + 1e-12
    assert not any("missing" in w for w in meas.warnings), meas.warnings


def test_the_batch_path_stores_what_the_frame_by_frame_path_does(
        ref: Measurement, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    dbc, db = _dbc(tmp_path, MUX_DBC, "mux.dbc")
    log = _write(tmp_path / "mux.log", mux_frames(db, ref, [0, 1, 2, 7, 1]))
    m = get_model("quarter2")
    batch = DecodeListener(m, dbc, MUX_MAP, capacity=1 << 12)
    blocks: list[int] = []
    push_many = PageSplit.push_many

    def spy(self: PageSplit, t: np.ndarray, rows: np.ndarray) -> None:
        blocks.append(t.size)
        push_many(self, t, rows)

    monkeypatch.setattr(PageSplit, "push_many", spy)
    feed_log(batch, log)
    assert sum(blocks) == ref.t.size   # every frame through the array path
    one = frame_by_frame(DecodeListener(m, dbc, MUX_MAP, capacity=1 << 12, batch_size=1))
    for msg in read_log(log):
        one.on_message_received(msg)
    a, b = snapshot(batch), snapshot(one)
    assert a == b
    assert set(batch.buffer.sources) == {"Chassis", "Chassis[Page=0]", "Chassis[Page=1]"}
    k = np.arange(ref.t.size)
    assert batch.buffer.sources["Chassis[Page=1]"].n == np.count_nonzero(np.isin(k % 5, [1, 4]))


NESTED_DBC = MUX_DBC.replace(' SG_ Road :', ' SG_ Sub m3M : 24|8@1+ (1,0) [0|255] "" ECU\n'
                                           ' SG_ Pitch m1 : 48|8@1+ (1,0) [0|255] "" ECU\n'
                                           ' SG_ Road :') + """
SG_MUL_VAL_ 512 Height Page 0-0;
SG_MUL_VAL_ 512 Wheel Page 1-1;
SG_MUL_VAL_ 512 Temp Page 2-2;
SG_MUL_VAL_ 512 Sub Page 3-3;
SG_MUL_VAL_ 512 Pitch Sub 1-1;
"""


def test_nested_multiplexing_is_one_line_naming_the_signal(ref: Measurement,
                                                           tmp_path: Path) -> None:
    dbc, db = _dbc(tmp_path, NESTED_DBC, "nested.dbc")
    log = _write(tmp_path / "mux.log", mux_frames(db, ref, [0, 1]))
    with pytest.raises(InputError, match=r"x1=Chassis\.Pitch: signal Chassis\.Pitch is sent "
                                         r"only when Sub = 1, and Sub only when Page = 3: "
                                         r"nested multiplexing"):
        load_log_as_measurement(log, "quarter2", dbc, ["x1=Chassis.Pitch"])
    # the inner multiplexer itself is one page of the outer one: decoded
    meas, _ = load_log_as_measurement(log, "quarter2", dbc, ["x1=Chassis.Height",
                                                             "x2=Chassis.Sub"])
    # only page 0 arrives of the pages mapped: its own 4 ms interval is the grid step
    np.testing.assert_allclose(meas.measured["x1"], ref.measured["x1"][::2], rtol=0, atol=5e-6)
    assert "x2" not in meas.measured   # page 3 never sent: no sample, as an absent column


def _estimates(args: list[str]) -> list[dict[str, Any]]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["monitor", "--model", "quarter2", *args, *FIX, "--window", "2",
                     "--step", "1", "--jsonl", "--no-inspection"]) == 0
    return [json.loads(x) for x in out.getvalue().splitlines() if x.strip()]


def test_monitor_windows_of_pages_are_fitted_as_plain_ones(tmp_path: Path) -> None:
    m = get_model("quarter2")
    t, road, x0 = make_scenario(m, "bump", duration=5.0, fs=500.0, t0=0.2)
    sim = simulate(m, m.defaults(), t, road, x0)
    rec = Measurement(t=t, road={"r": sim["r"]}, measured={"x1": sim["x1"], "x2": sim["x2"]})
    mdbc, mdb = _dbc(tmp_path, MUX_DBC, "mux.dbc")
    pdbc, pdb = _dbc(tmp_path, PLAIN_DBC, "plain.dbc")
    mux = _estimates(["--input", str(_write(tmp_path / "mux.log", mux_frames(mdb, rec, [0, 1]))),
                      "--dbc", str(mdbc), *[x for e in MUX_MAP for x in ("--map", e)]])
    plain = _estimates(["--input", str(_write(tmp_path / "plain.log", plain_frames(pdb, rec))),
                        "--dbc", str(pdbc), *[x for e in PLAIN_MAP for x in ("--map", e)]])
    # the half-empty cells of each page are not a gap: the same windows are fitted
    assert not any("missing" in str(e.get("reason", "")) for e in mux), mux
    got = [e for e in mux if e["type"] == "estimate"]
    want = [e for e in plain if e["type"] == "estimate"]
    assert len(got) == len(want) >= 2
    for a, b in zip(got, want):
        assert a["t"] == pytest.approx(b["t"])
        assert _rel(a["params"], b["params"]) < 0.05


def test_a_real_gap_in_a_page_is_still_reported(ref: Measurement, tmp_path: Path) -> None:
    dbc, db = _dbc(tmp_path, MUX_DBC, "mux.dbc")
    frames = mux_frames(db, ref, [0, 1])
    log = _write(tmp_path / "gap.log", frames[:400] + frames[440:])   # 20 samples per page lost
    meas, _ = load_log_as_measurement(log, "quarter2", dbc, MUX_MAP)
    assert meas.t.size == ref.t.size
    for ch, first in (("x1", 400), ("x2", 401)):
        miss = np.flatnonzero(np.isnan(meas.measured[ch]))
        # the other page's cells plus the 20 samples lost
        assert miss.size == ref.t.size - (ref.t.size - 40 + (ch == "x1")) // 2
        assert np.isnan(meas.measured[ch][first:first + 40:2]).all()
    gaps = [w for w in meas.warnings if "samples missing" in w]
    assert len(gaps) == 3, meas.warnings   # x1, x2 and the road (every frame)
    for ch, n in (("x1", 41), ("x2", 41)):
        assert any(f"channel {ch}: {n} of {ref.t.size} samples missing in 1 gap(s)" in w
                   and w.endswith("(a sample every 2 grid cells)") for w in gaps), gaps
    assert any("channel r: 40 of" in w and "grid cells" not in w for w in gaps), gaps


def test_ekf_monitor_on_pages_filters_each_channel_when_its_page_comes(tmp_path: Path) -> None:
    """The EKF takes each page's channels at the samples they come on (the other page's
    cells are missing entries of the update, not gaps): no restart, estimates as on the
    plain log's within the filter's own spread."""
    m = get_model("quarter2")
    t, road, x0 = make_scenario(m, "iso8608", duration=12.0, fs=500.0)
    sim = simulate(m, m.defaults(), t, road, x0)
    rec = Measurement(t=t, road={"r": sim["r"]}, measured={"x1": sim["x1"], "x2": sim["x2"]})
    mdbc, mdb = _dbc(tmp_path, MUX_DBC, "mux.dbc")
    pdbc, pdb = _dbc(tmp_path, PLAIN_DBC, "plain.dbc")
    mux = _estimates(["--input", str(_write(tmp_path / "mux.log", mux_frames(mdb, rec, [0, 1]))),
                      "--dbc", str(mdbc), *[x for e in MUX_MAP for x in ("--map", e)],
                      "--baseline", "ekf"])
    plain = _estimates(["--input", str(_write(tmp_path / "plain.log", plain_frames(pdb, rec))),
                        "--dbc", str(pdbc), *[x for e in PLAIN_MAP for x in ("--map", e)],
                        "--baseline", "ekf"])
    got = [e for e in mux if e["type"] == "estimate"]
    want = [e for e in plain if e["type"] == "estimate"]
    assert len(got) == len(want) >= 8
    assert mux[-1]["restarts"] == 0 and mux[-1]["divergences"] == 0
    assert not any(e.get("gaps") for e in got)
    for a, b in zip(got[-3:], want[-3:]):
        assert a["t"] == pytest.approx(b["t"])
        for k in ("c1", "k1", "k2"):
            assert a["params"][k] == pytest.approx(b["params"][k], rel=0.05), k
    for k in ("c1", "k1", "k2"):
        assert got[-1]["params"][k] == pytest.approx(m.defaults()[k], rel=0.05), k
