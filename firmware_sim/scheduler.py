"""A fixed-rate cooperative scheduler, as on a microcontroller with a timer tick; a tick
starting more than one period late is an *overrun* (counted, never skipped)."""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Callable


@dataclass
class Task:
    """A periodic task: ``fn(tick)`` runs when ``tick % every == 0``."""

    name: str
    every: int
    fn: Callable[[int], None]


@dataclass
class SchedulerStats:
    """Base ticks run, overruns (started over a period late), wall-clock duration (s)."""

    ticks: int = 0
    overruns: int = 0
    wall: float = 0.0


class Scheduler:
    """Fixed-rate scheduler with wall-clock pacing (``speed`` 0: as fast as possible)."""

    def __init__(self, tick_hz: float, speed: float = 1.0) -> None:
        if speed < 0:
            raise ValueError(f"speed must be >= 0, got {speed}")
        self.tick_hz = float(tick_hz)
        self.period = 1.0 / self.tick_hz
        self.speed = float(speed)
        self.tasks: list[Task] = []

    def add_task(self, name: str, rate_hz: float, fn: Callable[[int], None]) -> None:
        """Run ``fn(tick)`` at ``rate_hz`` (rounded to a whole number of base ticks)."""
        self.tasks.append(Task(name, max(1, int(round(self.tick_hz / rate_hz))), fn))

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
                elif now - target > wall_per_tick:
                    stats.overruns += 1
            for task in tasks:
                if k % task.every == 0:
                    task.fn(k)
            stats.ticks += 1
        stats.wall = clock() - wall0
        return stats
