"""Command-line options of the subcommands that read CAN data (``--map``, ``--config``):
:func:`add_can_arguments` on the parser, then :func:`command_config` and :func:`can_inputs`
on the parsed arguments. ``--dbc`` stays defined by each command.
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
    """Read ``--config`` and copy onto ``args`` its ``[can]`` ``channel``/``j1939_source`` (as
    ``can_channel``/``j1939_source``) and, when ``command`` reads it, every ``[fit]`` key."""
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
