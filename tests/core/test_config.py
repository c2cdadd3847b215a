"""The ``--config`` TOML file: checked key by key (one line naming the file, ``table.key``,
expected and got; exit 2), documented key by key, and loaded into the monitor's option
objects."""
from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from matplotlib.image import imread

from estimator.stream.config import WindowOptions
from estimator.stream.pipeline import monitor_spec
from suspid.cli import main
from suspid.cli._config import SCHEMA, TABLES, load_config
from suspid.errors import InputError
from suspid.models import get_model
from tests.conftest import write_config

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs" / "configuration.md"
EXAMPLE = REPO / "docs" / "suspid.example.toml"


@pytest.mark.parametrize(("text", "message"), [
    ("[window]\nbudgt = 3\n", "unknown key window.budgt; expected one of decimate, budget"),
    ("[wndow]\nbudget = 30\n", "unknown table [wndow]; expected one of [can], [fit]"),
    ("[window]\nbudget = 5\n", "window.budget: expected an integer >= 10, got 5 (integer)"),
    ("[window]\nbudget = 30.5\n", "window.budget: expected an integer >= 10, got 30.5 (float)"),
    ("[window]\nsigma_floor = \"a\"\n",
     "window.sigma_floor: expected a number >= 0 and <= 1, got 'a' (string)"),
    ("[window]\ndrift = \"c1\"\n",
     "window.drift: expected a list of parameter names, got 'c1' (string)"),
    ("[window]\noffset = \"drop\"\n",
     "window.offset: expected one of 'remove', 'keep', got 'drop' (string)"),
    ("[alert]\nconfidence = 1.0\n",
     "alert.confidence: expected a number > 0.5 and < 1, got 1.0 (float)"),
    ("[live]\nidle_timeout_s = -1\n",
     "live.idle_timeout_s: expected a number >= 0 (s), got -1 (integer)"),
    ("[live]\nslcan_timestamps = 1\n",
     "live.slcan_timestamps: expected true or false, got 1 (integer)"),
    ("[fit]\nx0 = [0, 1]\nrestarts = true\n",
     "fit.restarts: expected an integer >= 0, got True (boolean)"),
    ("window = 3\n", "window: expected a table [window], got 3 (integer)"),
    ("[window\n", "invalid TOML"),
])
def test_bad_files_are_one_line_naming_file_key_expected_and_got(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, message: str) -> None:
    path = write_config(tmp_path, text)
    with pytest.raises(InputError) as ei:
        load_config(path)
    assert str(ei.value).startswith(f"{path}: ") and message in str(ei.value)
    rc = main(["monitor", "--model", "quarter2", "--input", "no-such.log", "--config", path,
               "--jsonl"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and err.startswith(f"error: {path}: ")


def test_a_missing_file_is_named(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    rc = main(["identify", "--model", "quarter2", "--input", "x.csv", "--config",
               str(tmp_path / "nope.toml")])
    assert rc == 2
    assert capsys.readouterr().err == f"error: {tmp_path / 'nope.toml'}: no such configuration file\n"


def test_values_are_converted_and_dbc_is_relative_to_the_file(tmp_path: Path) -> None:
    cfg = load_config(write_config(tmp_path, '[can]\ndbc = "my.dbc"\nchannel = 2\n'
                                             '[window]\nbudget = 30\ndrift = []\n'
                                             'road_fusion_hz = 10\n[fit]\nx0 = [0, 0.5]\n'
                                             '[map]\nx1 = "Height.Body * 0.001"\n'))
    assert cfg.get("can", "dbc") == str(tmp_path / "my.dbc")
    assert cfg.get("can", "channel") == "2"
    assert cfg.table("window") == {"budget": 30, "drift": (), "road_fusion_hz": 10.0}
    assert cfg.fields("window", {"budget": "maxfev"}) == {"maxfev": 30, "drift": (),
                                                          "road_fusion_hz": 10.0}
    assert cfg.get("fit", "x0") == "0.0,0.5"
    assert cfg.signal_map is not None and cfg.signal_map.channels() == ["x1"]
    assert cfg.signal_map.dbc == tmp_path / "my.dbc"
    assert load_config(None).table("window") == {}


def test_the_window_table_reaches_the_monitor_spec(tmp_path: Path) -> None:
    """``[window]`` keys become :class:`WindowConfig` fields through ``WindowOptions``; the
    unset ones keep the model's defaults."""
    q2 = get_model("quarter2")
    fix = {"m1": 300.0, "m2": 40.0}
    base = monitor_spec(q2, fix=fix, fs=500.0).config
    cfg = load_config(write_config(tmp_path, "[window]\nbudget = 33\nsigma_floor = 0.02\n"
                                             "drift = []\n"))
    spec = monitor_spec(q2, fix=fix, fs=500.0,
                        window=WindowOptions(window_s=4.0,
                                             **cfg.fields("window", {"budget": "maxfev"})))
    c = spec.config
    assert (c.maxfev, c.sigma_floor, c.drift, c.window_s, c.step_s) == (33, 0.02, (), 4.0, 2.0)
    assert base.maxfev != 33 and base.drift == ("c1", "k1")
    assert c.first_maxfev == base.first_maxfev and c.road_fusion_hz == base.road_fusion_hz


def test_monitor_runs_with_the_live_and_monitor_tables(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """``[monitor] summary = false`` drops the closing line; ``[window] first_budget`` is the
    first window's evaluation budget (65 evaluations without it)."""
    csv = tmp_path / "q2.csv"
    assert main(["simulate", "--model", "quarter2", "--scenario", "iso8608", "--duration", "8",
                 "--fs", "200", "--out", str(csv)]) == 0
    capsys.readouterr()
    args = ["monitor", "--model", "quarter2", "--input", str(csv), "--fix", "m1=300",
            "--fix", "m2=40", "--fix", "c2=300", "--fix", "k2=200000", "--window", "2",
            "--step", "1", "--no-inspection", "--jsonl"]
    assert main(args) == 0
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert lines[-1]["type"] == "summary"
    first = [d["nfev"] for d in lines if d["type"] == "estimate"][0]
    config = write_config(tmp_path, "[monitor]\nsummary = false\n[window]\nfirst_budget = 20\n")
    assert main(args + ["--config", config]) == 0
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert lines and all(d["type"] != "summary" for d in lines)
    assert first > 20 and [d["nfev"] for d in lines if d["type"] == "estimate"][0] <= 20


def test_every_key_is_documented_with_unit_and_default() -> None:
    text = DOCS.read_text(encoding="utf-8")
    for table, keys in SCHEMA.items():
        assert f"### `[{table}]`" in text, table
        section = text.split(f"### `[{table}]`", 1)[1].split("\n### ", 1)[0]
        for name, key in keys.items():
            row = re.search(rf"^\| `{name}` \|(.*)\|$", section, re.M)
            assert row is not None, f"{table}.{name}"
            cells = [c.strip() for c in row.group(1).split("|")]
            assert cells[1] == (key.unit or "-") and cells[2] == key.default, f"{table}.{name}"


def test_the_example_file_loads_and_shows_every_key() -> None:
    cfg = load_config(EXAMPLE)
    text = EXAMPLE.read_text(encoding="utf-8")
    for table, keys in SCHEMA.items():
        assert f"[{table}]" in text
        for name in keys:
            assert re.search(rf"^#? ?{name} = ", text, re.M), f"{table}.{name}"
    assert cfg.get("window", "offset") == "remove"
    # the example sets nothing a command would not take by default
    assert "restarts" not in cfg.table("fit")


def test_each_command_reads_known_tables() -> None:
    assert all(set(ts) <= set(SCHEMA) for ts in TABLES.values())
    assert {t for ts in TABLES.values() for t in ts} == set(SCHEMA)


def test_compare_takes_the_tables_and_plots_every_monitored_parameter(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``compare --config``: ``[ekf] q``, ``[alert] forecast_horizon_s`` and ``[window] budget``
    reach the report; ``--plot`` draws one panel per monitored parameter (c1 and k1 here:
    the figure is 9 x 7 in at 110 dpi, one panel would be 9 x 4.5)."""
    config = write_config(tmp_path, "[ekf]\nq = 0.01\n[alert]\nforecast_horizon_s = 30\n"
                                    "[window]\nbudget = 50\n")
    png = tmp_path / "cmp.png"
    assert main(["compare", "--model", "quarter2", "--duration", "30", "--fs", "100",
                 "--config", config, "--plot", str(png), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["ekf"]["q_param"] == 0.01 and out["forecast_horizon_s"] == 30.0
    assert out["window"]["budget"] == 50 and sorted(out["nominal"]) == ["c1", "k1"]
    height, width = imread(png).shape[:2]
    assert (width, height) == (990, 770)
