"""``suspid`` command line: a dispatcher over ``suspid/cli/<name>.py``, each with
``add_parser(subparsers)`` and ``run(args) -> exit status``. A :class:`~suspid.errors.SuspidError`
or usage error is one ``error: ...`` line on stderr, exit 2 (``--debug``: the traceback).
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

# small matrices: BLAS threads only add contention. Set before numpy loads; a user's setting wins
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

#: subcommands in ``suspid --help``'s order with their one-line help (listed without importing
#: any module; each ``add_parser`` uses the same words)
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
        """As argparse's, but unknown options are reported by the subcommand given."""
        ns, extras = self.parse_known_args(args, namespace)
        if extras:
            prog = getattr(ns, "_prog", self.prog)
            sys.stderr.write(f"error: {prog}: unrecognized arguments: {' '.join(extras)}\n")
            raise SystemExit(2)
        return ns

    def _get_values(self, action: argparse.Action, arg_strings: list[str]) -> object:
        # Python 3.11's argparse drops an explicit "--" value ("--fs=--"): convert it like any
        if action.option_strings and action.nargs is None and arg_strings == ["--"]:
            value = self._get_value(action, "--")
            self._check_value(action, value)
            return value
        return super()._get_values(action, arg_strings)


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """Build the top-level parser with just the subcommand ``only`` (``None``: the listing of
    every subcommand, none imported)."""
    parser = _Parser(
        prog="suspid",
        description="Identify, monitor and diagnose vehicle suspension parameters "
        "(masses, springs, dampers) from sensor data and CAN logs.",
    )
    parser.add_argument("--version", action="version", version=f"suspid {__version__}")
    parser.add_argument("--debug", action="store_true", help="show Python tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    if only is None:
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
        # the reader of stdout went away (``| head -1``): stop quietly, fd 1 at /dev/null
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            os.close(devnull)
        except (OSError, ValueError):   # no real stdout (captured, closed): nothing to flush
            pass
        return 0
    except OSError as exc:
        # last resort for a file a subcommand opened without its own check
        if debug:
            raise
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        sys.stderr.write(f"error: {where}{_one_line(exc.strerror or str(exc))}\n")
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
