"""A constant offset in a road or position column: a sensor zero not at the rest position.

Such a static level is something no parameter set can produce. At fixed parameters the
residual is affine in the offsets, so the best offsets follow from one small linear
least-squares problem (:func:`find_offset`). Candidates: the road columns together and
each measured position channel alone (a road offset ``d`` and a position offset ``-d``
look alike to the model, so a channel is named first).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from estimator.identify.problem import OutputErrorProblem
from estimator.identify.misfit import NOISE_FLOOR, noise_floor_ratio
from suspid.effects import SensorOffset
from suspid.io.csvio import Measurement
from suspid.models.base import FloatArray, SuspensionModel

#: share of the weighted sum of squares an offset must leave at most to count as found
OFFSET_SHARE = 0.25

#: standard errors an offset must exceed to be named (a road column without one is left out)
SIGMAS = 3.0

#: shift (channel units) used to form the residual's exact affine dependence on an offset
_PROBE = 1e-2


@dataclass
class Offset:
    """Constant offsets found in road columns (``kind`` ``"road"``) or one measured position
    channel (``"channel"``): column -> how far it reads above the rest position (SI), and
    the normalised output-error cost with the offsets in and removed.
    """

    kind: str
    values: dict[str, float]
    cost_before: float
    cost_after: float

    @property
    def share(self) -> float:
        """Share of the weighted sum of squares the offsets leave (0 = all of it explained)."""
        return self.cost_after / self.cost_before if self.cost_before > 0 else 1.0

    def effects(self) -> list[SensorOffset]:
        """The offsets as ``sensor_offset`` effects of :mod:`suspid.effects`, one per column."""
        return [SensorOffset(channel=c, offset=d) for c, d in self.values.items()]

    def remove(self, meas: Measurement) -> Measurement:
        """``meas`` with the offsets subtracted from their columns (a new measurement)."""
        road = dict(meas.road)
        measured = dict(meas.measured)
        for e in self.effects():
            if self.kind == "road":
                road = e.compensate(meas.t, road)
            else:
                measured = e.compensate(meas.t, measured)
        return dataclasses.replace(meas, road=road, measured=measured,
                                   warnings=list(meas.warnings))

    def to_json(self, removed: bool) -> dict[str, Any]:
        """The JSON's ``offset``: ``kind``, ``values`` (SI), ``removed``, ``share`` and ``effects``."""
        return {"kind": self.kind, "values": dict(self.values), "removed": removed,
                "share": self.share,
                "effects": [f"sensor_offset:channel={c},offset={d:.6g}"
                            for c, d in self.values.items()]}

    def describe(self, model: SuspensionModel) -> str:
        """The columns and their offsets, e.g. ``road column r reads +0.01 m`` (SI units)."""
        parts = [f"{c} reads {d:+.3g} {(model.column_units(c) or ('SI',))[0]}"
                 for c, d in self.values.items()]
        what = "road column" if self.kind == "road" else "position channel"
        return f"{what}{'s' if len(parts) > 1 else ''} " + ", ".join(parts)

    def warning(self, model: SuspensionModel, removed: bool) -> str:
        """One line naming the columns, the offsets with units and the remedy."""
        head = (f"offset: {self.describe(model)} at the rest position, where the model "
                "expects 0 (a sensor zero not at rest: a static level no parameter can "
                f"produce, {100 * (1 - self.share):.1f} % of the misfit at the start)")
        if removed:
            return head + "; removed before the fit (--offset keep fits the record as it is)"
        return head + ("; kept (--offset keep), so the fit is not meaningful: subtract it from "
                       "the column, or let suspid remove it (--offset remove, the default)")


def _with_shift(meas: Measurement, kind: str, column: str, d: float) -> Measurement:
    """``meas`` with ``d`` subtracted from one road (``kind="road"``) or measured column."""
    road, measured = dict(meas.road), dict(meas.measured)
    target = road if kind == "road" else measured
    target[column] = np.asarray(target[column], dtype=float) - d
    return dataclasses.replace(meas, road=road, measured=measured)


def on_record(problem: OutputErrorProblem, meas: Measurement) -> OutputErrorProblem:
    """``problem`` (model, cost, initial-state handling, weights) on the record ``meas``."""
    return OutputErrorProblem(problem.model, meas, cost=problem.cost, x0=problem.x0,
                              weights=problem.weights, affine=problem.affine)


def _offsets(J: FloatArray, r0: FloatArray) -> tuple[FloatArray, float, list[int]]:
    """Offsets ``d`` minimising ``|r0 - J d|^2``, that minimum, and the columns whose offset
    exceeds ``SIGMAS`` standard errors.
    """
    d = np.asarray(np.linalg.lstsq(J, r0, rcond=None)[0], dtype=np.float64)
    rd = r0 - J @ d
    ss = float(rd @ rd)
    s2 = ss / max(r0.size - J.shape[1], 1)
    try:
        se = np.sqrt(np.clip(np.diag(np.linalg.pinv(J.T @ J)) * s2, 0.0, None))
    except np.linalg.LinAlgError:
        return d, ss, []
    return d, ss, [i for i in range(J.shape[1]) if abs(d[i]) > SIGMAS * se[i]]


def find_offset(problem: OutputErrorProblem, p: Mapping[str, float]) -> Offset | None:
    """The constant road or position offsets that best explain ``problem``'s misfit at ``p``
    (every parameter, SI): the candidate that lowers the cost most, when the fit at ``p`` is
    above the noise floor (``NOISE_FLOOR``) and the offsets leave at most ``OFFSET_SHARE``
    of its sum of squares; ``None`` otherwise.
    """
    model, meas = problem.model, problem.meas
    try:
        r0 = problem.residual_vector(p)
    except (np.linalg.LinAlgError, ValueError, FloatingPointError):
        return None
    ss0 = float(r0 @ r0)
    if not (math.isfinite(ss0) and ss0 > 0):
        return None
    if not noise_floor_ratio(problem, p) > NOISE_FLOOR:
        return None
    roads = [c for c in model.roads if c in meas.road and np.any(meas.road[c])]
    # a measured channel's zero before the road's: where both explain the record alike, the sensor's
    groups: list[tuple[str, list[str]]] = [("channel", [c]) for c in problem.channels
                                           if c in model.coords]
    groups += [("road", roads)] if roads else []
    best: Offset | None = None
    for kind, cols in groups:
        try:
            J = np.column_stack([(r0 - on_record(problem, _with_shift(meas, kind, c, _PROBE))
                                  .residual_vector(p)) / _PROBE for c in cols])
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            continue
        if not np.all(np.isfinite(J)):
            continue
        d, ss, keep = _offsets(J, r0)
        if len(keep) < len(cols):  # columns whose offset the record does not resolve
            cols = [cols[i] for i in keep]
            if not cols:
                continue
            d, ss, _ = _offsets(J[:, keep], r0)
        if best is None or ss / problem.scale < best.cost_after * (1.0 - 1e-6):
            best = Offset(kind, {c: float(v) for c, v in zip(cols, d)},
                          ss0 / problem.scale, ss / problem.scale)
    if best is None or best.share > OFFSET_SHARE:
        return None
    return best
