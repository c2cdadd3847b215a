"""Command-line options of the subcommands that read CAN data, and ``--config``.

``identify``, ``diagnose``, ``monitor``, ``compare`` and ``fleet`` call
:func:`add_can_arguments` on their parser (``--map``, ``--config``) and
:func:`command_config` then :func:`can_inputs` on the parsed arguments::

    add_can_arguments(parser, "identify")        # --map, --config
    cfg = command_config(args, "identify")     # reads --config, sets args.can_channel, ...
    dbc_path, signal_map = can_inputs(args, cfg)

The bus channel of a multi-bus log and a J1939 source address are the ``[can]`` table's
``channel`` and ``j1939_source`` (:mod:`suspid.cli._config`); ``--dbc`` is part of the
contract and stays defined by each command. ``simulate``, ``node`` and ``doe`` add
``--config`` alone (:func:`add_config_option`) for their own tables.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from suspid.can.signal_map import SignalMap, merge_maps
from suspid.cli._config import TABLES, Config, load_config


def add_config_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup,
                      command: str) -> None:
    """Add ``--config FILE``, its help naming the tables ``command`` reads."""
    tables = ", ".join(f"[{t}]" for t in TABLES[command])
    parser.add_argument("--config", metavar="FILE", default=None,
                        help=f"TOML file of tuning settings (tables {tables}; every key, unit "
                             "and default in docs/configuration.md)")


def add_can_arguments(parser: argparse.ArgumentParser, command: str) -> None:
    """Add ``--map`` and ``--config`` to a parser."""
    parser.add_argument("--map", metavar="CHANNEL=MSG.SIGNAL", action="append", default=[],
                        dest="signal_map",
                        help="map a DBC signal onto a model channel, e.g. "
                             "'x1_ddot=gnss_imu.AccelerationX-9.81' (repeatable; "
                             "[SCALE*]MSG.SIGNAL[*SCALE][+-OFFSET|-mean]; wins over the "
                             "--config file's [map]); default: the SuspidChannel attributes of "
                             "suspid's DBC")
    add_config_option(parser, command)


def command_config(args: argparse.Namespace, command: str) -> Config:
    """Read ``--config`` and copy its ``[can]`` and ``[fit]`` settings onto ``args``.

    ``args.can_channel`` and ``args.j1939_source`` become the ``[can]`` table's ``channel``
    and ``j1939_source`` (``None`` when not set); each key of ``[fit]`` (``restarts``,
    ``multistart``, ``polish``, ``data_start``) replaces the command's default when the
    command reads that table.

    Parameters
    ----------
    args : argparse.Namespace
    command : str
        The subcommand (the tables it reads: :data:`suspid.cli._config.TABLES`).

    Returns
    -------
    Config
    """
    cfg = load_config(getattr(args, "config", None))
    args.can_channel = cfg.get("can", "channel")
    args.j1939_source = cfg.get("can", "j1939_source")
    if "fit" in TABLES[command]:
        for key, value in cfg.table("fit").items():
            setattr(args, key, value)
    return cfg


def can_inputs(args: argparse.Namespace, cfg: Config) -> tuple[Path | None, SignalMap | None]:
    """``(dbc_path, signal_map)``: ``--dbc``, else the configuration's ``[can] dbc``, else a
    ``[map]``'s; the ``[map]`` table and the ``--map`` options (these win)."""
    maps: list[SignalMap | None] = [cfg.signal_map]
    if getattr(args, "signal_map", None):
        maps.append(SignalMap.from_strings(args.signal_map))
    smap = merge_maps(maps)
    dbc = getattr(args, "dbc", None) or cfg.get("can", "dbc")
    if dbc is None and smap is not None and smap.dbc is not None:
        dbc = smap.dbc
    return (Path(dbc) if dbc else None), smap
