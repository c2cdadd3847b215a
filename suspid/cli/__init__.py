"""``suspid`` command line: a thin dispatcher over one module per subcommand.

Each subcommand lives in ``suspid/cli/<name>.py`` and provides

``add_parser(subparsers) -> argparse.ArgumentParser``
    register the subcommand and its options;
``run(args) -> int``
    do the work and return the exit status.

Errors derived from :class:`suspid.errors.SuspidError` (and argparse usage errors) become a
single ``error: ...`` line on stderr with exit status 2; ``--debug`` shows the traceback.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
from typing import NoReturn, Sequence

# neither imports numpy: the thread settings below still come first
from suspid import __version__
from suspid.errors import SuspidError

# The identifier works on small matrices: BLAS threads only add contention (5-10x slower
# per evaluation on a loaded 2-core machine). Set before numpy loads; a user's setting wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

#: Subcommand modules, in the order ``suspid --help`` lists them, with their one-line help
#: (each module's ``add_parser`` uses the same words; ``tests/core/test_cli.py`` checks).
#: ``suspid --help`` lists them from this table alone, without importing any module.
SUBCOMMANDS: dict[str, str] = {
    "simulate": "simulate a model and write a measurement CSV",
    "identify": "identify suspension parameters from a measurement",
    "diagnose": "find the effect a model lacks from its residual, add it, refit",
    "encode": "encode a measurement CSV as a CAN log (.log/.asc/.blf/.trc/.mf4)",
    "node": "run the simulated sensor node on a CAN bus",
    "monitor": "watch a suspension on a CAN stream and alert on worn parts",
    "compare": "compare the NM window identifier with the EKF on one stream",
    "doe": "run the seed's Taguchi designs of experiments (L16/L27)",
    "fleet": "identify every drive log of a fleet; trends and forecasts",
}


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose usage errors are one ``error:`` line and exit status 2."""

    def error(self, message: str) -> NoReturn:
        sys.stderr.write(f"error: {self.prog}: {message}\n")
        raise SystemExit(2)

    def parse_args(self, args: Sequence[str] | None = None,  # type: ignore[override]
                   namespace: argparse.Namespace | None = None) -> argparse.Namespace:
        """As argparse's, but unknown options are reported by the subcommand that was given
        (``suspid monitor: unrecognized arguments: --foo``), not by ``suspid``."""
        ns, extras = self.parse_known_args(args, namespace)
        if extras:
            prog = getattr(ns, "_prog", self.prog)
            sys.stderr.write(f"error: {prog}: unrecognized arguments: {' '.join(extras)}\n")
            raise SystemExit(2)
        return ns

    def _get_values(self, action: argparse.Action, arg_strings: list[str]) -> object:
        # Python 3.11's argparse drops an explicit "--" value ("--fs=--") and hands the
        # subcommand an empty list instead of a usage error; convert it like any value
        if action.option_strings and action.nargs is None and arg_strings == ["--"]:
            value = self._get_value(action, "--")
            self._check_value(action, value)
            return value
        return super()._get_values(action, arg_strings)


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """Build the top-level parser.

    Parameters
    ----------
    only : str, optional
        Register just this subcommand (``main`` passes the one on the command line: each
        subcommand module imports what it needs, and importing all eight costs ~0.15 s of
        every start). ``None`` registers every subcommand (``suspid --help``).
    """
    parser = _Parser(
        prog="suspid",
        description="Identify, monitor and diagnose vehicle suspension parameters "
        "(masses, springs, dampers) from sensor data and CAN logs.",
    )
    parser.add_argument("--version", action="version", version=f"suspid {__version__}")
    parser.add_argument("--debug", action="store_true", help="show Python tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    if only is None:
        # the listing only: one line per subcommand from the table, no module imported
        for name, summary in SUBCOMMANDS.items():
            sub.add_parser(name, help=summary)
        return parser
    module = importlib.import_module(f"suspid.cli.{only}")
    p = module.add_parser(sub)
    p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                   help="show Python tracebacks on errors")
    p.set_defaults(_run=module.run, _prog=p.prog)
    return parser


def _one_line(text: str) -> str:
    """``text`` with every run of whitespace (newlines included) replaced by one space."""
    return " ".join(text.split())


def _subcommand(argv: Sequence[str]) -> str | None:
    """The subcommand named on the command line (its first non-option word), if known."""
    for word in argv:
        if not word.startswith("-"):
            return word if word in SUBCOMMANDS else None
        if word == "--":
            return None
    return None


def _drop_stdout() -> None:
    """Point file descriptor 1 at ``/dev/null`` (after its reader closed the pipe)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):   # no real stdout (captured, closed): nothing to flush
        pass


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``suspid`` console script."""
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    try:
        parser = build_parser(_subcommand(argv))
        args = parser.parse_args(argv)
        if not getattr(args, "_run", None):
            parser.print_help()
            return 2
        return int(args._run(args) or 0)
    except SuspidError as exc:
        if debug:
            raise
        sys.stderr.write(f"error: {_one_line(str(exc))}\n")
        return 2
    except BrokenPipeError:
        # the reader of stdout went away (``suspid monitor --jsonl | head -1``): stop quietly;
        # stdout goes to /dev/null so the interpreter's final flush cannot fail again
        _drop_stdout()
        return 0
    except OSError as exc:
        # last resort for a file a subcommand opened without its own check (an output
        # path in a missing directory, a directory given as a file, no permission, ...)
        if debug:
            raise
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        sys.stderr.write(f"error: {where}{_one_line(exc.strerror or str(exc))}\n")
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
