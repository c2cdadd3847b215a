"""Option groups the fitting commands share, and the monitor's option objects from the options
and the ``--config`` file. Each command words its own help; names, types and defaults live here.
"""
from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from estimator.choices import COSTS, OFFSET_MODES, ROAD_MODES
from suspid.cli._can import can_inputs, command_config
from suspid.cli._common import parse_assignments, positive_int
from suspid.cli._lazy import lazy_names
from suspid.models import get_model

if TYPE_CHECKING:
    from estimator.identify import Parameters
    from estimator.identify.inputs import read_input
    from estimator.stream.config import AlertOptions, EkfOptions, WindowOptions
    from suspid.cli._config import Config
    from suspid.io.csvio import Measurement
    from suspid.models.base import SuspensionModel
else:
    # the estimator loads when a command runs
    AlertOptions, EkfOptions, WindowOptions = lazy_names(
        "estimator.stream.config", "AlertOptions", "EkfOptions", "WindowOptions")
    Parameters, = lazy_names("estimator.identify", "Parameters")
    read_input, = lazy_names("estimator.identify.inputs", "read_input")


def add_fit_options(p: argparse.ArgumentParser, restarts: int, cost: str, maxfev: str,
                    offset: str | None = None, group: argparse._ActionsContainer | None = None) -> None:
    """Add ``--cost``, ``--maxfev`` and, with its help ``offset``, ``--offset remove|keep`` (to
    ``group``, default ``p``; each command words the help) and the defaults of the ``[fit]``
    settings (``restarts`` the command's Nelder-Mead restarts)."""
    g = p if group is None else group
    g.add_argument("--cost", choices=list(COSTS), default="sse", help=cost)
    g.add_argument("--maxfev", type=positive_int, default=None, help=maxfev)
    if offset is not None:
        g.add_argument("--offset", choices=list(OFFSET_MODES), default="remove", help=offset)
    p.set_defaults(restarts=restarts, multistart=4, polish=True, data_start=True, x0="estimate")


def fit_inputs(args: argparse.Namespace, command: str
               ) -> tuple[SuspensionModel, Parameters, Measurement, dict[str, object] | None]:
    """The model, its parameters (``--fix``, ``--init``), the record (``--input``: a CSV or a CAN
    log) and its frame statistics (CAN input, else ``None``) of a fitting command."""
    model = get_model(args.model)
    cfg = command_config(args, command)
    params = Parameters.for_model(model, fix=parse_assignments(args.fix, "--fix"),
                                  init=parse_assignments(args.init, "--init"))
    dbc_path, signal_map = can_inputs(args, cfg)
    meas, frames = read_input(args.input, model, dbc_path, signal_map, channel=args.can_channel,
                              j1939_source=args.j1939_source)
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


#: ``[window]`` keys whose ``WindowOptions`` field is named differently
WINDOW_FIELDS = {"budget": "maxfev", "first_budget": "first_maxfev"}
#: ``[alert]`` keys of :class:`~estimator.stream.config.AlertOptions` (the rest are fleet's)
ALERT_KEYS = ("confidence", "persistence_s", "hysteresis", "forecast_horizon_s")


def options_from_config(args: argparse.Namespace, cfg: Config
                        ) -> tuple[WindowOptions, AlertOptions, EkfOptions]:
    """``--window``, ``--step``, ``--alert-drop`` and the ``[window]``, ``[alert]``, ``[ekf]``
    tables as the monitor's option objects."""
    window = WindowOptions(window_s=args.window, step_s=args.step,
                           **cfg.fields("window", WINDOW_FIELDS))
    alert = AlertOptions(drop=args.alert_drop,
                         **{k: v for k, v in cfg.table("alert").items() if k in ALERT_KEYS})
    return window, alert, EkfOptions(**cfg.table("ekf"))
