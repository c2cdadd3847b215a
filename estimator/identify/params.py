"""Parameters in the style of lmfit: value, ``vary``, ``min``, ``max`` (a fixed mass is vary=False)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterator, Mapping

from suspid.errors import UsageError
from suspid.models.base import SuspensionModel


@dataclass
class Parameter:
    """One model parameter: its current ``value`` (SI; the starting guess before a fit),
    whether it varies (``False`` holds it at ``value``: known, e.g. a weighed mass) and its
    bounds (SI; the identifier works in log coordinates, so ``min`` must be >= 0).
    """

    name: str
    value: float
    vary: bool = True
    min: float = 0.0
    max: float = math.inf


class Parameters(Mapping[str, Parameter]):
    """Ordered collection of :class:`Parameter` for one model."""

    def __init__(self, items: list[Parameter]) -> None:
        self._p = {p.name: p for p in items}

    @classmethod
    def for_model(cls, model: SuspensionModel, fix: Mapping[str, float] | None = None,
                  init: Mapping[str, float] | None = None) -> "Parameters":
        """Parameters of ``model`` starting at its documented defaults, ``fix`` (``name ->
        value``) held fixed and ``init`` (``name -> starting value``) of free ones.
        """
        fix = dict(fix or {})
        init = dict(init or {})
        for name in list(fix) + list(init):
            model.spec(name)  # raises UsageError naming the valid parameters
        both = set(fix) & set(init)
        if both:
            raise UsageError(f"parameter(s) {', '.join(sorted(both))} given both --fix and --init")
        items = []
        for spec in model.params:
            v = fix.get(spec.name, init.get(spec.name, spec.default))
            if not (v > 0 and math.isfinite(v)):
                raise UsageError(f"parameter {spec.name}: expected a finite value > 0 {spec.unit}, got {v}")
            items.append(Parameter(spec.name, float(v), spec.name not in fix))
        return cls(items)

    def __getitem__(self, key: str) -> Parameter:
        return self._p[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._p)

    def __len__(self) -> int:
        return len(self._p)

    def valuesdict(self) -> dict[str, float]:
        """``name -> value``."""
        return {k: p.value for k, p in self._p.items()}

    @property
    def free(self) -> list[str]:
        """Names of the varying parameters."""
        return [k for k, p in self._p.items() if p.vary]

    @property
    def fixed(self) -> list[str]:
        """Names of the fixed parameters."""
        return [k for k, p in self._p.items() if not p.vary]

    def copy(self) -> "Parameters":
        return Parameters([Parameter(p.name, p.value, p.vary, p.min, p.max) for p in self._p.values()])

    def with_values(self, values: Mapping[str, float]) -> "Parameters":
        """A copy with the ``values`` (SI) set."""
        out = self.copy()
        for k, v in values.items():
            out[k].value = float(v)
        return out
