"""Command-line options shared by the subcommands that read CAN data.

``identify``, ``diagnose``, ``monitor`` and ``compare`` can call :func:`add_can_arguments`
on their parser and :func:`can_inputs` on the parsed arguments::

    add_can_arguments(parser)            # --map CHANNEL=MSG.SIGNAL..., --map-file PATH, --can-channel
    dbc_path, signal_map = can_inputs(args)
    meas, frames = load_log_as_measurement(args.input, model, dbc_path, signal_map,
                                           channel=args.can_channel)

(``--dbc`` is part of the contract and stays defined by each command unless ``dbc=True``.)

A command that reads a live bus adds :func:`add_receive_arguments` (``--rx-buffer``,
``--slcan-timestamps``).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from suspid.can.signal_map import SignalMap, merge_maps


#: default length of the live receiver's buffer (s of data at the DBC's frame rate, at least
#: a saturated 1 Mbit/s bus; ``estimator.stream.drivers.receive_capacity``)
RECEIVE_BUFFER_S = 10.0


def positive_seconds(text: str) -> float:
    """argparse ``type``: a finite number of seconds > 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds > 0, got {text!r}") from None
    if not 0 < v < float("inf"):
        raise argparse.ArgumentTypeError(f"expected seconds > 0, got {text!r}")
    return v


def add_receive_arguments(parser: "argparse.ArgumentParser | argparse._ArgumentGroup") -> None:
    """Add the live receiver's options: ``--rx-buffer SECONDS`` and ``--slcan-timestamps``."""
    parser.add_argument("--rx-buffer", type=positive_seconds, default=RECEIVE_BUFFER_S,
                        metavar="SECONDS",
                        help="frames the receiver thread may hold while the decoder and the "
                             "fits lag behind, in seconds of data at the DBC's frame rate "
                             "(every message at its GenMsgCycleTime, at least 10 k frames/s: "
                             f"a saturated 1 Mbit/s bus); default {RECEIVE_BUFFER_S:g}")
    parser.add_argument("--slcan-timestamps", action="store_true",
                        help="--interface slcan: switch the adapter's timestamp mode on "
                             "(Lawicel Z1) and time each frame by the adapter's clock "
                             "(ms, unwrapped over its 60 s period) instead of the host's "
                             "arrival time")


def add_can_arguments(parser: argparse.ArgumentParser, dbc: bool = False) -> None:
    """Add ``--map``, ``--map-file``, ``--can-channel`` and ``--j1939-source`` (and ``--dbc``
    if ``dbc``) to a parser."""
    if dbc:
        parser.add_argument("--dbc", metavar="PATH",
                            help="DBC of the CAN data (default: suspid's dbc/suspension.dbc)")
    parser.add_argument("--map", metavar="CHANNEL=MSG.SIGNAL", action="append", default=[],
                        dest="signal_map",
                        help="map a DBC signal onto a model channel, e.g. "
                             "'x1_ddot=gnss_imu.AccelerationX-9.81' (repeatable; "
                             "[SCALE*]MSG.SIGNAL[*SCALE][+-OFFSET|-mean]); default: the "
                             "SuspidChannel attributes of suspid's DBC")
    parser.add_argument("--map-file", metavar="PATH", dest="signal_map_file",
                        help="signal map file (.toml or .json: a [map] table, optional dbc = ...)")
    parser.add_argument("--can-channel", metavar="CH", default=None,
                        help="decode only this bus channel of a CAN log that records several, "
                             "as the file names it: 1, 2, ... for ASC/BLF channels, TRC buses "
                             "and MDF4 BusChannel (CAN1 and ch1 also read as 1), the interface "
                             "name (can0, can1) for candump; frames of the other channels are "
                             "counted (frames.other_channel), not decoded. Default: every "
                             "channel, with a warning when the sensor's messages are on more "
                             "than one")
    parser.add_argument("--j1939-source", metavar="ADDR", default=None,
                        help="a J1939 DBC (ProtocolType J1939): decode its parameter groups "
                             "from this source address only (0..253, e.g. 0x00 the engine); "
                             "frames are matched to the DBC by PGN whatever their source "
                             "address. Default: the first sender of each PGN, with a warning "
                             "naming every sender when a mapped PGN has several")


def can_inputs(args: argparse.Namespace) -> tuple[Path | None, SignalMap | None]:
    """``(dbc_path, signal_map)`` from parsed options (the map file's ``dbc`` if no ``--dbc``)."""
    maps = []
    if getattr(args, "signal_map_file", None):
        maps.append(SignalMap.from_file(args.signal_map_file))
    if getattr(args, "signal_map", None):
        maps.append(SignalMap.from_strings(args.signal_map))
    smap = merge_maps(maps)
    dbc = getattr(args, "dbc", None)
    if dbc is None and smap is not None and smap.dbc is not None:
        dbc = smap.dbc
    return (Path(dbc) if dbc else None), smap
