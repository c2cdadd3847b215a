"""``suspid node``: run the simulated sensor-node firmware on a python-can bus."""
from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING

from firmware_sim.scenarios import SCENARIOS
from suspid.cli._can import add_config_option
from suspid.cli._config import load_config
from suspid.cli._common import parse_assignments
from suspid.cli._lazy import lazy_names
from suspid.errors import UsageError
from suspid.models import MODELS

if TYPE_CHECKING:
    import can

    from firmware_sim.faults import FaultConfig
    from firmware_sim.node import NodeConfig, SensorNode
    from firmware_sim.transport import SlcanPtyBus, open_bus
    from suspid.can.logs import log_format, open_log_writer
else:
    FaultConfig, = lazy_names("firmware_sim.faults", "FaultConfig")
    NodeConfig, SensorNode = lazy_names("firmware_sim.node", "NodeConfig", "SensorNode")
    SlcanPtyBus, open_bus = lazy_names("firmware_sim.transport", "SlcanPtyBus", "open_bus")
    log_format, open_log_writer = lazy_names("suspid.can.logs", "log_format", "open_log_writer")


def _speed(text: str) -> float:
    t = text.strip().lower()
    if t in ("max", "0"):
        return 0.0
    try:
        v = float(t)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number or 'max', got {text!r}") from None
    if not (v >= 0 and v < float("inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0 (0 or 'max' = as fast as "
                                         f"possible), got {text!r}")
    return v


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``suspid node``."""
    p = subparsers.add_parser(
        "node", help="run the simulated sensor node on a CAN bus",
        description="Run the simulated suspension sensor-node firmware: a fixed-rate "
        "scheduler (sensor task at --rate, status at 10 Hz) reads the plant (the model), adds "
        "sensor noise, packs frames per the DBC with E2E counter and CRC-8 and sends them on a "
        "python-can bus. '--interface slcan --channel pty' makes the node a simulated SLCAN "
        "USB-CAN adapter on a pseudo-terminal and prints 'pty: /dev/pts/N' as the first "
        "stdout line; the node starts when a host opens the channel "
        "(e.g. suspid monitor --interface slcan --channel /dev/pts/N). At the end one JSON "
        "summary line is printed.")
    p.add_argument("--scenario", required=True, choices=list(SCENARIOS) + ["iso8608"],
                   help="initial, curb, bump, random (ISO 8608 road), damper-wear (c1 falls "
                        "linearly from --wear-start to --wear-to x nominal at the end)")
    p.add_argument("--interface", default="virtual",
                   help="python-can interface: virtual (default), slcan, socketcan, ...")
    p.add_argument("--channel", default="suspid",
                   help="python-can channel; 'pty' with slcan creates the simulated adapter "
                        "(default 'suspid')")
    p.add_argument("--duration", type=float, metavar="S",
                   help="run length in seconds of data time (default: 5 s for initial/curb/bump, "
                        "30 s random, 150 s damper-wear)")
    p.add_argument("--speed", type=_speed, default=1.0, metavar="X",
                   help="X times real time; 0 or 'max' = as fast as possible (default 1)")
    p.add_argument("--model", choices=list(MODELS), default="quarter2",
                   help="plant model and message set: quarter1/quarter2 -> QC_*, half4 -> HC_*, "
                        "full7 -> FC_* (default quarter2)")
    p.add_argument("--rate", type=float, default=500.0, metavar="HZ",
                   help="sensor task rate, 500-1000 Hz typical (default 500)")
    p.add_argument("--channels", metavar="LIST",
                   help="comma-separated channels to send (default: every motion channel of "
                        "the model and the roads); ride heights (d, d_dot; d1..d4) may be named, "
                        "and the sets 'production' (body accelerations and ride heights) and "
                        "'accelerometers' (every coordinate's acceleration), which send no road "
                        "and no wheel motion")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="plant parameter (SI), e.g. --param c1=1200; repeatable")
    p.add_argument("--noise", type=float, default=1.0, metavar="SCALE",
                   help="sensor noise as a multiple of the defaults (20 um, 1 mm/s, 0.02 m/s^2 "
                        "standard deviation); 0 = noise-free (default 1)")
    p.add_argument("--fault", action="append", default=[], metavar="KIND=ARGS",
                   help="inject a fault (repeatable): loss=P, burst=RATE_HZ:LENGTH_S, "
                        "stuck=CHANNEL:START_S:LENGTH_S, bitflip=P, late=P:DELAY_S, "
                        "busoff=AT_S:LENGTH_S")
    p.add_argument("--effect", action="append", default=[], metavar="NAME:KEY=VAL,...",
                   help="inject an effect the estimator is not told about (any of suspid "
                        "diagnose's effects, e.g. coulomb_friction:F=120 or "
                        "sensor_delay:channels=x2+x2_dot,delay_s=0.008); repeatable")
    p.add_argument("--seed", type=int, default=0, help="seed of road, noise and faults (default 0)")
    p.add_argument("--wear-start", type=float, default=20.0, metavar="S",
                   help="damper-wear: time the damping starts to fall (default 20 s)")
    p.add_argument("--wear-to", type=float, default=0.5, metavar="FRACTION",
                   help="damper-wear: damping at the end as a fraction of nominal (default 0.5)")
    p.add_argument("--dbc", metavar="PATH", help="DBC (default: suspid's dbc/suspension.dbc)")
    p.add_argument("--log", metavar="PATH",
                   help="also record every transmitted frame to this CAN log (.log/.asc/.blf/...)")
    add_config_option(p, "node")
    return p


def run(args: argparse.Namespace) -> int:
    """Run the node; exit 0 after the scenario ends."""
    pty = load_config(args.config).table("node")
    open_timeout, linger = pty.get("open_timeout_s", 60.0), pty.get("linger_s", 3.0)
    channels = [x.strip() for x in args.channels.split(",") if x.strip()] if args.channels else None
    cfg = NodeConfig(model=args.model, scenario=args.scenario, duration=args.duration,
                     rate=args.rate, speed=args.speed, noise=args.noise, channels=channels,
                     params=parse_assignments(args.param, "--param"), seed=args.seed,
                     wear_start=args.wear_start, wear_to=args.wear_to,
                     faults=FaultConfig.parse(args.fault))
    node = SensorNode(cfg, args.dbc, effects=args.effect or None)
    if args.log:
        log_format(args.log, "--log")
    bus = open_bus(args.interface, args.channel)
    writer = None
    try:
        if isinstance(bus, SlcanPtyBus):
            sys.stdout.write(f"pty: {bus.path}\n")
            sys.stdout.flush()
            if not bus.wait_open(open_timeout):
                raise UsageError(f"no host opened the SLCAN channel on {bus.path} within "
                                 f"{open_timeout:g} s (open it with python-can's slcan "
                                 "interface; node.open_timeout_s of --config)")
        target: can.BusABC | _Tee = bus
        if args.log:
            writer = open_log_writer(args.log)
            target = _Tee(bus, writer)
        if isinstance(bus, SlcanPtyBus):
            # keep receiving (a late alert frame) until the host closes or node.linger_s ends
            summary = node.run(target, linger=linger,
                               linger_until=bus.closed_by_host)
            bus.drain(5.0)
            summary_extra = {"slcan": {"path": bus.path, "overflows": bus.overflows,
                                       "dropped_closed": bus.dropped_closed,
                                       "host_frames": bus.host_frames}}
        else:
            summary = node.run(target)
            summary_extra = {}
    finally:
        if writer is not None:
            writer.stop()
        bus.shutdown()
    out = {"node": summary.as_dict(), **summary_extra}
    sys.stdout.write(json.dumps(out) + "\n")
    sys.stdout.flush()
    return 0


class _Tee:
    """Bus proxy that also records every sent frame to a log writer."""

    def __init__(self, bus: can.BusABC, writer: can.io.generic.MessageWriter) -> None:
        self._bus = bus
        self._writer = writer

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self._bus.send(msg, timeout)
        self._writer.on_message_received(msg)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        return self._bus.recv(timeout)
