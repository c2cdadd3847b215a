"""The command line stays small: at most 25 options per subcommand and 150 in all, counted
from the argparse parsers (``tools/count_options.py``); unknown options name the
subcommand."""
from __future__ import annotations

import pytest

from suspid.cli import SUBCOMMANDS, main
from tools.count_options import (MAX_PER_COMMAND, MAX_TOTAL, long_options, option_counts,
                                 subcommand_parser)


def test_no_subcommand_has_more_than_25_options_and_150_in_all() -> None:
    counts = option_counts()
    assert set(counts) == set(SUBCOMMANDS)
    over = {name: n for name, n in counts.items() if n > MAX_PER_COMMAND}
    assert not over, f"more than {MAX_PER_COMMAND} options: {over}"
    assert sum(counts.values()) <= MAX_TOTAL, counts
    assert (MAX_PER_COMMAND, MAX_TOTAL) == (25, 150)


def test_the_count_includes_help_and_debug() -> None:
    opts = long_options(subcommand_parser("encode"))
    assert opts[0] == "--help" and "--debug" in opts and len(opts) == len(set(opts))


@pytest.mark.parametrize("command", ["monitor", "compare", "fleet", "identify", "diagnose"])
def test_the_contract_options_stay(command: str) -> None:
    """Every option ``/work/shared/CONTRACT.md`` names for the command is still accepted."""
    contract = {
        "identify": ["--model", "--input", "--dbc", "--fix", "--init", "--cost", "--json", "--road"],
        "diagnose": ["--model", "--input", "--dbc", "--fix", "--init", "--cost", "--json", "--road"],
        "monitor": ["--model", "--input", "--interface", "--channel", "--dbc", "--fix",
                    "--nominal", "--alert-drop", "--baseline", "--jsonl", "--road"],
        "compare": ["--road"],
        "fleet": ["--model", "--input", "--dbc", "--map", "--fix", "--init", "--nominal",
                  "--alert-drop", "--scheduler", "--workers", "--db", "--report", "--json",
                  "--road"],
    }[command]
    have = set(long_options(subcommand_parser(command)))
    assert not set(contract) - have


def test_unknown_option_names_the_subcommand(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as ei:
        main(["monitor", "--model", "quarter2", "--input", "x.log", "--foo"])
    assert ei.value.code == 2
    assert capsys.readouterr().err == "error: suspid monitor: unrecognized arguments: --foo\n"


def test_a_removed_option_is_an_unknown_one(capsys: pytest.CaptureFixture[str]) -> None:
    """Tuning moved to ``--config``: the former option is refused by the subcommand."""
    with pytest.raises(SystemExit) as ei:
        main(["identify", "--model", "quarter2", "--input", "x.csv", "--restarts", "2"])
    assert ei.value.code == 2
    assert capsys.readouterr().err == ("error: suspid identify: unrecognized arguments: "
                                       "--restarts 2\n")


@pytest.mark.parametrize("command", list(SUBCOMMANDS))
def test_help_describes_every_option(command: str) -> None:
    """``compare --help`` once listed --alert-drop, --window and --step without a word."""
    p = subcommand_parser(command)
    missing = [a.option_strings[0] for a in p._actions if a.option_strings and not a.help]
    assert not missing
