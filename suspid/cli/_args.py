"""Option groups and checks the fitting commands share (``diagnose``, ``fleet``; ``identify``'s set;
``--offset`` of ``identify`` and ``fleet``).

Each command words its own help; the option names, types, defaults and metavars and the
checks of their values live here once.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass

from typing import TYPE_CHECKING

from estimator.choices import COSTS, OFFSET_MODES, ROAD_MODES
from suspid.cli._common import load_measurement, model_from_args, params_from_args, positive_int
from suspid.errors import UsageError

if TYPE_CHECKING:
    from estimator.identify import Parameters
    from suspid.io.csvio import Measurement
    from suspid.models.base import SuspensionModel


@dataclass(frozen=True)
class FitHelp:
    """Help text of the identifier's options, as one command words it.

    Attributes
    ----------
    cost, x0, restarts, maxfev, multistart, polish : str
        Help of ``--cost``, ``--x0``, ``--restarts``, ``--maxfev``, ``--multistart`` and
        ``--no-polish``.
    """

    cost: str
    x0: str
    restarts: str
    maxfev: str
    multistart: str
    polish: str


def add_fit_options(p: argparse._ActionsContainer, helps: FitHelp, restarts: int) -> None:
    """Add the identifier's settings ``--cost``, ``--x0``, ``--restarts``, ``--maxfev``,
    ``--multistart`` and ``--no-polish`` (in this order) to a parser or argument group.

    Parameters
    ----------
    p : argparse parser or argument group
    helps : FitHelp
        The command's help text of each option.
    restarts : int
        Default of ``--restarts`` (Nelder-Mead restarts).
    """
    p.add_argument("--cost", choices=list(COSTS), default="sse", help=helps.cost)
    p.add_argument("--x0", default="estimate", metavar="estimate|rest|V1,V2,...", help=helps.x0)
    p.add_argument("--restarts", type=int, default=restarts, help=helps.restarts)
    p.add_argument("--maxfev", type=positive_int, default=None, help=helps.maxfev)
    p.add_argument("--multistart", type=int, default=4, metavar="N", help=helps.multistart)
    p.add_argument("--no-polish", dest="polish", action="store_false", help=helps.polish)


def add_offset_option(p: argparse._ActionsContainer, help_text: str) -> None:
    """Add ``--offset remove|keep`` (default ``remove``): what the identification does with a
    constant road or position offset it finds (:func:`estimator.identify.record.identify_record`).

    Parameters
    ----------
    p : argparse parser or argument group
    help_text : str
        The command's help of the option.
    """
    p.add_argument("--offset", choices=list(OFFSET_MODES), default="remove", help=help_text)


def check_counts(args: argparse.Namespace, *options: str) -> None:
    """Raise :class:`~suspid.errors.UsageError` unless each count option is >= 0.

    Parameters
    ----------
    args : argparse.Namespace
    *options : str
        Attribute names (``"restarts"``, ``"multistart"``); the message names ``--NAME``.
    """
    for opt in options:
        v = getattr(args, opt)
        if v < 0:
            raise UsageError(f"--{opt}: expected >= 0, got {v}")


def comma_list(text: str | None) -> list[str] | None:
    """The items of a comma-separated option (``--channels x1,x2``), stripped, empty ones
    dropped; ``None`` when the option is not given (or empty)."""
    if not text:
        return None
    return [x.strip() for x in text.split(",") if x.strip()]


def fit_inputs(args: argparse.Namespace
               ) -> tuple[SuspensionModel, Parameters, Measurement, dict[str, object] | None]:
    """The model, its parameters, the record and its frame statistics of a fitting command.

    ``--model``, ``--fix``/``--init`` (``--restarts`` checked), ``--multistart`` checked,
    then ``--input`` read (a CSV, or a CAN log decoded with ``--dbc``).

    Returns
    -------
    model : SuspensionModel
    params : Parameters
    meas : Measurement
    frames : dict or None
        Accepted/rejected frame counts for CAN input.
    """
    model = model_from_args(args)
    params = params_from_args(args, model)
    check_counts(args, "multistart")
    meas, frames = load_measurement(args, model)
    return model, params, meas, frames


def add_road_option(p: argparse._ActionsContainer) -> None:
    """``--road measured|zero|unknown`` (default: chosen from the record and named in a warning)."""
    p.add_argument("--road", choices=list(ROAD_MODES), default=None,
                   help="measured: the record's road columns/messages are the input; zero: no "
                        "road input (a free response); unknown: the road is never measured "
                        "(every road vehicle): fit the body equations on body accelerations "
                        "and ride heights (or wheel motion), identifying every strut's damper "
                        "and spring and reporting what the record cannot determine as such. "
                        "Default: measured with road columns, else zero for a free response "
                        "and unknown for driving data, named in a warning")
