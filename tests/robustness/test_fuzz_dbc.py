"""Fuzzing DBC loading: any text either loads or fails with one InputError line naming the file."""
from __future__ import annotations

import re
from pathlib import Path

import pytest
from cantools.database.can import Database
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from estimator.decode import DecodeListener
from suspid.can.dbc import default_dbc_path, load_dbc
from suspid.errors import InputError, SuspidError, UsageError

DBC_LINES = default_dbc_path().read_text().splitlines()
GARBAGE = st.text(alphabet=st.characters(codec="utf-8", exclude_categories=["Cs"]), max_size=40)
_SETTINGS = settings(max_examples=40, deadline=None,
                     suppress_health_check=[HealthCheck.function_scoped_fixture])


def _load(tmp_path: Path, text: str) -> Database | InputError:
    p = tmp_path / "fuzz.dbc"
    p.write_text(text, encoding="utf-8")
    try:
        return load_dbc(p)
    except InputError as exc:
        return exc


def _check_error(exc: InputError) -> None:
    msg = str(exc)
    assert "\n" not in msg and msg.split(": ")[0].endswith("fuzz.dbc")


@pytest.mark.slow
@_SETTINGS
@given(data=st.data())
def test_mutated_suspension_dbc_loads_or_names_the_line(tmp_path: Path, data: st.DataObject) -> None:
    """Delete, duplicate or replace one line of our DBC with garbage, or cut the file short."""
    lines = list(DBC_LINES)
    k = data.draw(st.integers(0, len(lines) - 1), label="line")
    op = data.draw(st.sampled_from(["delete", "garbage", "insert", "truncate", "dup"]), label="op")
    if op == "delete":
        del lines[k]
    elif op == "garbage":
        lines[k] = data.draw(GARBAGE, label="text")
    elif op == "insert":
        lines.insert(k, data.draw(GARBAGE, label="text"))
    elif op == "dup":
        lines.insert(k, lines[k])
    else:
        cut = data.draw(st.integers(0, len(lines[k])), label="col")
        lines = lines[:k] + [lines[k][:cut]]
    got = _load(tmp_path, "\n".join(lines) + "\n")
    if isinstance(got, InputError):
        _check_error(got)
        if "Invalid syntax" in str(got):
            # the parse error names the line (1-based) it stopped at
            m = re.search(r"line (\d+)", str(got))
            assert m and 1 <= int(m.group(1)) <= len(lines) + 1
    else:
        assert got.messages


@_SETTINGS
@given(text=st.text(max_size=300))
def test_random_text_is_rejected_cleanly(tmp_path: Path, text: str) -> None:
    got = _load(tmp_path, text)
    if isinstance(got, InputError):
        _check_error(got)
    else:  # a random text that happens to define a message
        assert got.messages


def test_syntax_error_names_line_and_column(tmp_path: Path) -> None:
    lines = list(DBC_LINES)
    k = next(i for i, line in enumerate(lines) if line.startswith("BO_ "))
    lines[k] = "BO_ 272 QC_Body 8 SensorNode"  # colon missing
    got = _load(tmp_path, "\n".join(lines))
    assert isinstance(got, InputError)
    assert f"line {k + 1}" in str(got) and "column" in str(got)


@pytest.mark.parametrize("text, expect", [
    ("", "Invalid syntax at line 1"),
    ("VERSION \"\"\n", "defines no message"),
    ("\x00\x01garbage", "Invalid syntax"),
])
def test_empty_and_messageless_dbc(tmp_path: Path, text: str, expect: str) -> None:
    got = _load(tmp_path, text)
    assert isinstance(got, InputError) and expect in str(got)


def test_directory_and_missing_dbc(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="is a directory, expected a DBC file"):
        load_dbc(tmp_path)
    with pytest.raises(InputError, match="nope.dbc: no such DBC file"):
        load_dbc(tmp_path / "nope.dbc")


def test_dbc_without_our_messages_names_the_fix(tmp_path: Path) -> None:
    p = tmp_path / "foreign.dbc"
    p.write_text('VERSION ""\nBO_ 1 Foo: 8 X\n SG_ A : 0|8@1+ (1,0) [0|1] "" X\n')
    db = load_dbc(p)
    with pytest.raises(UsageError, match=r"foreign.dbc declares no channel of model quarter2.*--map"):
        DecodeListener("quarter2", db)
    # a map that names a message the DBC lacks names the entry and the known messages
    with pytest.raises(SuspidError, match=r"QC_Body.*not in .*foreign.dbc.*Foo"):
        DecodeListener("quarter2", db, ["x1=QC_Body.Disp"])
