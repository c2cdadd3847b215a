"""A fixed-rate cooperative scheduler, as on a microcontroller with a timer tick.

One base tick (the sensor task period, e.g. 2 ms at 500 Hz) drives every task; a task runs
every ``n`` ticks (the 10 Hz status task every 50 ticks at 500 Hz). Pacing maps data time to
wall time: ``speed = 1`` is real time, ``speed = X`` runs X times faster, ``speed = 0``
runs as fast as possible. A tick that starts more than one period late is an *overrun*
(counted, never skipped: a sample is never dropped because the host is slow).
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Callable


@dataclass
class Task:
    """A periodic task: ``fn(tick)`` runs when ``tick % every == offset``."""

    name: str
    every: int
    fn: Callable[[int], None]
    offset: int = 0
    runs: int = 0


@dataclass
class SchedulerStats:
    """What the scheduler observed.

    Attributes
    ----------
    ticks : int
        Base ticks executed.
    overruns : int
        Ticks that started more than one period behind the pacing clock.
    max_late : float
        Largest lateness (s, wall time) of a tick start.
    wall : float
        Wall-clock duration of the run (s).
    runs : dict
        Executions per task.
    """

    ticks: int = 0
    overruns: int = 0
    max_late: float = 0.0
    wall: float = 0.0
    runs: dict[str, int] = field(default_factory=dict)


class Scheduler:
    """Fixed-rate scheduler with wall-clock pacing.

    Parameters
    ----------
    tick_hz : float
        Base tick rate (Hz).
    speed : float
        Data time per wall time; 0 = as fast as possible.
    """

    def __init__(self, tick_hz: float, speed: float = 1.0) -> None:
        if not tick_hz > 0:
            raise ValueError(f"tick rate must be > 0 Hz, got {tick_hz}")
        if speed < 0:
            raise ValueError(f"speed must be >= 0, got {speed}")
        self.tick_hz = float(tick_hz)
        self.period = 1.0 / self.tick_hz
        self.speed = float(speed)
        self.tasks: list[Task] = []

    def add_task(self, name: str, rate_hz: float, fn: Callable[[int], None], offset: int = 0) -> Task:
        """Run ``fn(tick)`` at ``rate_hz`` (rounded to a whole number of base ticks)."""
        every = max(1, int(round(self.tick_hz / rate_hz)))
        task = Task(name, every, fn, offset % every)
        self.tasks.append(task)
        return task

    def run(self, n_ticks: int, stop: threading.Event | None = None) -> SchedulerStats:
        """Execute ``n_ticks`` base ticks (fewer if ``stop`` is set)."""
        stats = SchedulerStats()
        wall0 = time.perf_counter()
        sleep = time.sleep
        clock = time.perf_counter
        pace = self.speed > 0
        wall_per_tick = self.period / self.speed if pace else 0.0
        tasks = self.tasks
        for k in range(n_ticks):
            if stop is not None and stop.is_set():
                break
            if pace:
                target = wall0 + k * wall_per_tick
                now = clock()
                if target > now:
                    sleep(target - now)
                else:
                    late = now - target
                    if late > stats.max_late:
                        stats.max_late = late
                    if late > wall_per_tick:
                        stats.overruns += 1
            for task in tasks:
                if k % task.every == task.offset:
                    task.fn(k)
                    task.runs += 1
            stats.ticks += 1
        stats.wall = clock() - wall0
        stats.runs = {t.name: t.runs for t in tasks}
        return stats
