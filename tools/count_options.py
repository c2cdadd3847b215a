"""Count the options of every ``suspid`` subcommand, from the argparse parsers themselves.

Usage::

    .venv/bin/python tools/count_options.py

Prints one line per subcommand (the options its parser accepts: every action with a
``--long`` name, ``-h/--help`` and ``--debug`` included) and the total.
``tests/core/test_cli_options.py`` holds the limits (:data:`MAX_PER_COMMAND`,
:data:`MAX_TOTAL`).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from suspid.cli import SUBCOMMANDS, build_parser  # noqa: E402  (the worktree's package, above)

#: most options one subcommand may have
MAX_PER_COMMAND = 25
#: most options of all subcommands together
MAX_TOTAL = 150


def subcommand_parser(name: str) -> argparse.ArgumentParser:
    """The parser of subcommand ``name`` (as ``suspid NAME ...`` builds it)."""
    top = build_parser(name)
    for action in top._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action.choices[name]
    raise LookupError(f"suspid has no subcommand {name!r}")


def long_options(parser: argparse.ArgumentParser) -> list[str]:
    """The first ``--long`` name of each option ``parser`` accepts, in definition order."""
    out: list[str] = []
    for action in parser._actions:
        longs = [s for s in action.option_strings if s.startswith("--")]
        if longs:
            out.append(longs[0])
    return out


def option_counts() -> dict[str, int]:
    """Subcommand -> number of options, in ``suspid --help`` order."""
    return {name: len(long_options(subcommand_parser(name))) for name in SUBCOMMANDS}


def main() -> int:
    counts = option_counts()
    for name, n in counts.items():
        print(f"{name:<10} {n:>4}")
    print(f"{'total':<10} {sum(counts.values()):>4}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
