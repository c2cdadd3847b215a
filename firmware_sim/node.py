"""The simulated suspension sensor node, written like its firmware: a scheduler runs the
sensor task (``SN_Sync`` and the sensor frames every tick), the status task (``SN_Status``)
and the rx task (keeps ``SUSPID_Alert`` frames); the :class:`CanDriver` applies
transmission faults. Each frame's ``timestamp`` is its data time (s since start).
"""
from __future__ import annotations

import heapq
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Protocol, Sequence

import can
import numpy as np
from cantools.database.can import Database

from firmware_sim.faults import FaultConfig, FaultInjector
from firmware_sim.plant import Plant
from firmware_sim.scenarios import build_scenario
from firmware_sim.scheduler import Scheduler, SchedulerStats
from suspid.can.codec import (FAULT_BITS, STATE_BUSOFF_RECOVERED, STATE_DEGRADED, STATE_RUNNING,
                              STATE_STOPPING, SensorEncoder, decode_alert, encode_status,
                              make_message)
from suspid.can.dbc import ALERT_MESSAGE, load_dbc
from suspid.errors import UsageError
from suspid.models import get_model
from suspid.models.base import CHANNEL_SETS, ForceFn, SuspensionModel
from suspid.effects import Effect

#: default sensor noise standard deviation (SI) by derivative order: position, velocity, acceleration
DEFAULT_NOISE = {0: 2e-5, 1: 1e-3, 2: 0.02}


class FrameBus(Protocol):
    """What the node needs of a bus: any python-can bus, or a proxy with these two methods."""

    def send(self, msg: can.Message, timeout: float | None = None) -> None: ...

    def recv(self, timeout: float | None = None) -> can.Message | None: ...


@dataclass
class NodeConfig:
    """Configuration of a node run: model and scenario (:mod:`firmware_sim.scenarios`), run
    length (s, default per scenario), sensor and status rates (Hz), pacing ``speed`` (0: as
    fast as possible), ``noise`` x :data:`DEFAULT_NOISE`, channels sent (names of
    :data:`~suspid.models.base.CHANNEL_SETS` allowed; default every motion and road),
    parameter overrides (SI), faults, seed, damper-wear schedule (s, fraction)."""

    model: str = "quarter2"
    scenario: str = "bump"
    duration: float | None = None
    rate: float = 500.0
    status_hz: float = 10.0
    speed: float = 1.0
    noise: float = 1.0
    channels: list[str] | None = None
    params: dict[str, float] = field(default_factory=dict)
    faults: FaultConfig = field(default_factory=FaultConfig)
    seed: int = 0
    wear_start: float = 20.0
    wear_to: float = 0.5


@dataclass
class NodeSummary:
    """What a node run did (printed as JSON by ``suspid node``)."""

    scenario: str
    model: str
    rate: float
    duration: float
    ticks: int = 0
    frames_sent: int = 0
    frames_dropped: dict[str, int] = field(default_factory=dict)
    tx_errors: int = 0
    busoff_count: int = 0
    rx_frames: int = 0
    alerts: list[dict[str, Any]] = field(default_factory=list)
    saturated: dict[str, int] = field(default_factory=dict)
    overruns: int = 0
    wall: float = 0.0
    events: dict[str, float] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


class CanDriver:
    """The node's CAN controller: transmission faults, late frames, bus-off, ``sink(msg)``."""

    def __init__(self, sink: Callable[[can.Message], None], faults: FaultInjector) -> None:
        self.sink = sink
        self.faults = faults
        self.sent = 0
        self.tx_errors = 0
        self._late: list[tuple[float, int, can.Message]] = []
        self._seq = 0

    def transmit(self, frame_id: int, data: bytearray, t: float) -> None:
        """Queue one frame for transmission at data time ``t`` (s)."""
        ok, delay = self.faults.transmit(t, data)
        if not ok:
            return
        msg = make_message(frame_id, data, t)
        if delay > 0:
            self._seq += 1
            heapq.heappush(self._late, (t + delay, self._seq, msg))
            return
        self._send(msg)

    def release(self, t: float) -> None:
        """Send the held-back (late) frames that are due at data time ``t``."""
        while self._late and self._late[0][0] <= t:
            due, _, msg = heapq.heappop(self._late)
            msg.timestamp = due
            if self.faults.in_busoff(due):
                self.faults.counts["busoff"] += 1
                continue
            self._send(msg)

    def _send(self, msg: can.Message) -> None:
        try:
            self.sink(msg)
            self.sent += 1
        except can.CanError:
            self.tx_errors += 1


class SensorNode:
    """The simulated sensor node of ``config``; ``model``, ``extra_forces`` ``f(t, x, u, params)`` and
    undeclared ``effects`` go into the plant."""

    def __init__(self, config: NodeConfig, dbc: str | Path | Database | None = None,
                 model: SuspensionModel | None = None,
                 extra_forces: Sequence[ForceFn] | None = None,
                 effects: Sequence[Effect | str | Mapping[str, object]] | None = None) -> None:
        self.config = config
        self.db = dbc if isinstance(dbc, Database) else load_dbc(dbc)
        self.model = model if model is not None else get_model(config.model)
        if not 1.0 <= config.rate <= 10000.0:
            raise UsageError(f"--rate must be within 1..10000 Hz (500-1000 typical), got {config.rate}")
        if not 0 < config.status_hz <= config.rate:
            raise UsageError(f"status rate must be in (0, {config.rate}] Hz, got {config.status_hz}")
        if not 0 <= config.noise < float("inf"):
            raise UsageError(f"--noise must be a finite number >= 0, got {config.noise}")
        self.setup = build_scenario(self.model, config.scenario, config.duration, config.rate,
                                    config.params, config.seed, config.wear_start, config.wear_to)
        self.plant = Plant(self.model, self.setup.params, self.setup.t, self.setup.road,
                           self.setup.x0, chunk_s=0.05 if self.setup.name == "damper-wear" else 1.0,
                           extra_forces=extra_forces, effects=effects)
        available = list(self.plant.channels)
        sets = [self.model.channel_set(n) if n in CHANNEL_SETS else [n] for n in config.channels or []]
        chans = (list(dict.fromkeys(c for s in sets for c in s)) if config.channels
                 else [c for c in available if c not in self.model.ride_height_channels])
        bad = [c for c in chans if c not in available]
        if bad:
            raise UsageError(f"channel(s) {', '.join(bad)} not available for model {self.model.name} "
                             f"and scenario {self.setup.name}; expected any of {', '.join(available)} "
                             f"or a set ({', '.join(CHANNEL_SETS)})")
        self.channels = chans
        for ch, _start, _len in config.faults.stuck:
            if ch not in chans:
                raise UsageError(f"--fault stuck={ch}:...: channel {ch!r} is not sent; expected one "
                                 f"of {', '.join(chans)}")
        self.encoder = SensorEncoder(self.db, self.model.name, chans)
        self.rng = np.random.default_rng(config.seed + 7919)
        self.noise = {c: DEFAULT_NOISE[c.endswith("_dot") + 2 * c.endswith("_ddot")] * config.noise
                      for c in chans}
        self.n_ticks = int(self.setup.t.size)
        self.period = 1.0 / config.rate
        self.faults = FaultInjector(config.faults, np.random.default_rng(config.seed + 104729),
                                    float(self.setup.t[-1]))
        self.sensor_set = self.model.sensor_set
        self.summary = NodeSummary(self.setup.name, self.model.name, config.rate,
                                   float(self.setup.t[-1]), events=dict(self.setup.events))
        self._status_counter = 0
        self._busoff_count = 0
        self._busoff_since_status = False
        self._last_status_t = -1.0
        self._sat_seen = 0
        self._driver: CanDriver | None = None
        self._bus: FrameBus | None = None
        try:
            self._alert_id = self.db.get_message_by_name(ALERT_MESSAGE).frame_id
        except KeyError:
            self._alert_id = -1

    def _need_driver(self) -> CanDriver:
        if self._driver is None:
            raise RuntimeError("the node's tasks run only inside run() or frames()")
        return self._driver

    def truth(self, t: float) -> Mapping[str, float]:
        """Plant parameters in force at data time ``t`` (s) -- the ground truth."""
        return self.setup.params(t)

    def _sensor_task(self, k: int) -> None:
        driver = self._need_driver()
        t = k * self.period
        driver.release(t)
        values = self.plant.sample(k)
        sample = {}
        rng = self.rng
        for c in self.channels:
            v = values[c]
            s = self.noise[c]
            sample[c] = v + s * float(rng.standard_normal()) if s else v
        self.faults.sensors(t, sample)
        fid, data = self.encoder.sync_frame(k, self.period)
        driver.transmit(fid, data, t)
        for fid, data in self.encoder.sample_frames(k, sample):
            driver.transmit(fid, data, t)
        self.summary.ticks += 1

    def _status_task(self, k: int, stopping: bool = False) -> None:
        driver = self._need_driver()
        t = k * self.period
        started = self.faults.busoff_started(self._last_status_t, t)
        if started:
            self._busoff_count += started
            self._busoff_since_status = True
        self._last_status_t = t
        if self.faults.in_busoff(t):
            return  # the controller is off the bus: the status is lost too
        flags = self.faults.flags(t)
        sat = sum(self.encoder.saturated.values())
        if sat > self._sat_seen:
            flags |= 1 << FAULT_BITS["saturation"]
            self._sat_seen = sat
        if self._busoff_since_status:
            flags |= 1 << FAULT_BITS["busoff"]
            state = STATE_BUSOFF_RECOVERED
            self._busoff_since_status = False
        elif stopping:
            state = STATE_STOPPING
        else:
            state = STATE_DEGRADED if flags else STATE_RUNNING
        fid, data = encode_status(self.db, self._status_counter, state, self.config.rate, flags,
                                  self._busoff_count, self.sensor_set)
        self._status_counter += 1
        driver.transmit(fid, data, t)

    def _rx_task(self, _k: int) -> None:
        bus = self._bus
        if bus is None:
            return
        while True:
            try:
                msg = bus.recv(0.0)
            except can.CanError:
                return
            if msg is None:
                return
            self.summary.rx_frames += 1
            if msg.arbitration_id == self._alert_id and not msg.is_error_frame:
                try:
                    alert = decode_alert(self.db, msg.data)
                except Exception:  # a malformed alert: count it only
                    continue
                self.summary.alerts.append(alert)

    def _scheduler(self, speed: float) -> Scheduler:
        sched = Scheduler(self.config.rate, speed)
        sched.add_task("sensor", self.config.rate, self._sensor_task)
        sched.add_task("status", self.config.status_hz, self._status_task)
        if self._bus is not None:
            sched.add_task("rx", self.config.rate, self._rx_task)
        return sched

    def _finish(self, stats: SchedulerStats) -> NodeSummary:
        driver = self._need_driver()
        driver.release(float("inf"))
        s = self.summary
        s.frames_sent = driver.sent
        s.tx_errors = driver.tx_errors
        s.frames_dropped = {k: v for k, v in self.faults.counts.items() if k != "stuck" and v}
        if self.faults.counts.get("stuck"):
            s.frames_dropped["stuck_samples"] = self.faults.counts["stuck"]
        s.busoff_count = self._busoff_count
        s.saturated = dict(self.encoder.saturated)
        s.overruns = stats.overruns
        s.wall = stats.wall
        return s

    def run(self, bus: FrameBus, speed: float | None = None,
            stop: threading.Event | None = None, linger: float = 0.0,
            linger_until: threading.Event | None = None) -> NodeSummary:
        """Run the scenario on a python-can bus (or a proxy with ``send`` and ``recv``);
        ``speed`` overrides ``config.speed``, ``stop`` ends the run early. After the last
        sample the node keeps receiving for ``linger`` s (wall) unless ``stop`` or
        ``linger_until`` (e.g. the SLCAN host closed the channel) is set."""
        self._bus = bus
        self._driver = CanDriver(bus.send, self.faults)
        sched = self._scheduler(self.config.speed if speed is None else speed)
        stats = sched.run(self.n_ticks, stop)
        self._status_task(max(0, stats.ticks - 1), stopping=True)
        deadline = time.perf_counter() + max(0.0, linger)
        while time.perf_counter() < deadline and not (stop is not None and stop.is_set()) \
                and not (linger_until is not None and linger_until.is_set()):
            self._rx_task(stats.ticks)
            time.sleep(0.01)
        self._rx_task(stats.ticks)
        return self._finish(stats)

    def frames(self) -> Iterator[can.Message]:
        """Every frame the node would send, in order, without a bus or pacing."""
        out: list[can.Message] = []
        self._bus = None
        self._driver = CanDriver(out.append, self.faults)
        sched = self._scheduler(0.0)
        for k in range(self.n_ticks):
            for task in sched.tasks:
                if k % task.every == 0:
                    task.fn(k)
            if out:
                yield from out
                out.clear()
        self._status_task(max(0, self.n_ticks - 1), stopping=True)
        self._finish(SchedulerStats(ticks=self.n_ticks))
        yield from out
