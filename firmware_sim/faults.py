"""Fault injection of the simulated node, ``--fault KIND=ARGS`` (repeatable; docs/can.md):
frame ``loss``, loss ``burst`` windows, ``stuck`` sensors, ``bitflip`` after the CRC,
``late`` frames, ``busoff`` windows; all random choices come from one seeded generator."""
from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Iterable

import numpy as np

from suspid.errors import UsageError

FAULT_KINDS = ("loss", "burst", "stuck", "bitflip", "late", "busoff")


@dataclass
class FaultConfig:
    """Parsed fault specification (see the module docstring; times in s, rates in Hz)."""

    loss: float = 0.0
    bursts: list[tuple[float, float]] = field(default_factory=list)
    stuck: list[tuple[str, float, float]] = field(default_factory=list)
    bitflip: float = 0.0
    late: tuple[float, float] | None = None
    busoff: list[tuple[float, float]] = field(default_factory=list)

    @classmethod
    def parse(cls, specs: Iterable[str], channels: Iterable[str] | None = None) -> "FaultConfig":
        """Parse ``KIND=ARGS`` strings (UsageError naming a bad spec and the expected form)."""
        cfg = cls()
        chans = set(channels) if channels is not None else None
        forms = {"loss": "loss=P", "burst": "burst=RATE_HZ:LENGTH_S",
                 "stuck": "stuck=CHANNEL:START_S:LENGTH_S", "bitflip": "bitflip=P",
                 "late": "late=P:DELAY_S", "busoff": "busoff=AT_S:LENGTH_S"}
        for spec in specs:
            kind, sep, arg = spec.partition("=")
            kind = kind.strip()
            if kind not in FAULT_KINDS or not sep:
                raise UsageError(f"--fault {spec!r}: expected one of "
                                 f"{', '.join(forms.values())}")
            parts = [a.strip() for a in arg.split(":")]
            num = functools.partial(_fault_number, spec, forms[kind])
            if len(parts) != forms[kind].count(":") + 1:
                raise UsageError(f"--fault {spec!r}: expected {forms[kind]}")
            inf = float("inf")
            if kind == "loss":
                cfg.loss = num(parts[0], 0, 1, "probability")
            elif kind == "bitflip":
                cfg.bitflip = num(parts[0], 0, 1, "probability")
            elif kind == "burst":
                cfg.bursts.append((num(parts[0], 0, 1e3, "rate"), num(parts[1], 0, inf, "length")))
            elif kind == "late":
                cfg.late = (num(parts[0], 0, 1, "probability"), num(parts[1], 0, 10, "delay"))
            elif kind == "busoff":
                cfg.busoff.append((num(parts[0], 0, inf, "time"), num(parts[1], 0, inf, "length")))
            else:
                ch = parts[0]
                if chans is not None and ch not in chans:
                    raise UsageError(f"--fault {spec!r}: channel {ch!r} is not sent; expected one "
                                     f"of {', '.join(sorted(chans))}")
                cfg.stuck.append((ch, num(parts[1], 0, inf, "start"), num(parts[2], 0, inf, "length")))
        return cfg


def _fault_number(spec: str, form: str, s: str, lo: float, hi: float, what: str) -> float:
    """Parse one number of a ``--fault`` spec, in ``[lo, hi]`` (else UsageError)."""
    try:
        v = float(s)
    except ValueError:
        raise UsageError(f"--fault {spec!r}: {what} must be a number, got {s!r} "
                         f"(form {form})") from None
    if not lo <= v <= hi:
        raise UsageError(f"--fault {spec!r}: {what} must be in [{lo:g}, {hi:g}], got {v:g}")
    return v


class FaultInjector:
    """Applies a :class:`FaultConfig` to the node's sensor values and transmissions."""

    def __init__(self, config: FaultConfig, rng: np.random.Generator, duration: float) -> None:
        self.config = config
        self.rng = rng
        self.counts = dict.fromkeys(FAULT_KINDS, 0)
        self._held: dict[str, float] = {}
        windows: list[tuple[float, float]] = []
        for rate, length in config.bursts:
            if rate <= 0:
                continue
            t = float(rng.exponential(1.0 / rate))
            while t < duration:
                windows.append((t, t + length))
                t += length + float(rng.exponential(1.0 / rate))
        self.burst_windows = sorted(windows)
        self.busoff_windows = sorted((a, a + n) for a, n in config.busoff)

    def sensors(self, t: float, values: dict[str, float]) -> dict[str, float]:
        """Apply stuck-sensor faults to one sample (in place) and return it."""
        for ch, start, length in self.config.stuck:
            if ch not in values:
                continue
            if start <= t < start + length:
                if ch not in self._held:
                    self._held[ch] = values[ch]
                values[ch] = self._held[ch]
                self.counts["stuck"] += 1
            else:
                self._held.pop(ch, None)
        return values

    def in_busoff(self, t: float) -> bool:
        """``True`` while the controller is bus-off at time ``t``."""
        return any(a <= t < b for a, b in self.busoff_windows)

    def busoff_started(self, t_prev: float, t: float) -> int:
        """Number of bus-off events starting in ``(t_prev, t]``."""
        return sum(1 for a, _ in self.busoff_windows if t_prev < a <= t)

    def transmit(self, t: float, data: bytearray) -> tuple[bool, float]:
        """The fate of one frame at ``t`` (s): ``(send, delay s)``; a bit flip changes ``data``."""
        cfg = self.config
        if self.busoff_windows and self.in_busoff(t):
            self.counts["busoff"] += 1
            return False, 0.0
        if self.burst_windows and any(a <= t < b for a, b in self.burst_windows):
            self.counts["burst"] += 1
            return False, 0.0
        rng = self.rng
        if cfg.loss and rng.random() < cfg.loss:
            self.counts["loss"] += 1
            return False, 0.0
        if cfg.bitflip and rng.random() < cfg.bitflip and data:
            bit = int(rng.integers(0, 8 * len(data)))
            data[bit // 8] ^= 1 << (bit % 8)
            self.counts["bitflip"] += 1
        if cfg.late and rng.random() < cfg.late[0]:
            self.counts["late"] += 1
            return True, cfg.late[1]
        return True, 0.0

    def flags(self, t: float) -> int:
        """SN_Status FaultFlags bits of the faults active at ``t``."""
        cfg = self.config
        stuck = any(s <= t < s + n for _, s, n in cfg.stuck)
        active = (cfg.loss, self.burst_windows, stuck, cfg.bitflip, cfg.late)
        return sum(1 << bit for bit, on in enumerate(active) if on)
