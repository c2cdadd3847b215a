"""A sensor zero not at rest, found on the stream's first excited window and removed from all.

As ``suspid identify`` does (:mod:`estimator.identify.offset`), :class:`OffsetStage` looks
once for a constant road or position offset and, with ``offset = "remove"``, subtracts it
from every window (``docs/monitoring.md``, "Sensor offset").
"""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from estimator.identify.offset import Offset
from estimator.identify.params import Parameters
from estimator.identify.problem import OutputErrorProblem
from estimator.identify.record import check_offset
from estimator.stream.config import WindowConfig
from estimator.stream.events import Notice
from estimator.stream.window import SlidingWindowIdentifier
from suspid.errors import UsageError
from suspid.io.csvio import Measurement
from suspid.models.base import FloatArray, SuspensionModel


class OffsetStage:
    """Look for a constant road or position offset once, then remove it from every window.

    ``params`` are the monitor's (the offset is judged at the window's data-driven start);
    ``config`` gives ``offset``, ``cost`` and the excitation thresholds. ``offset`` holds the
    offset found, ``t`` the end (s) of the window it was found on.
    """

    def __init__(self, model: SuspensionModel, params: Parameters, config: WindowConfig) -> None:
        self.model = model
        self.params = params
        self.config = config
        self.remove = config.offset == "remove"
        self.offset: Offset | None = None
        self.t = math.nan
        self.checked = False
        self._excited: SlidingWindowIdentifier | None = None

    def _check(self, t: FloatArray, data: Mapping[str, FloatArray]) -> Notice | None:
        # the model's measured channels and road columns in ``data``
        chans = [c for c in self.model.channels if c in data
                 and np.mean(np.isfinite(np.asarray(data[c], dtype=float))) > 0.5]
        roads = [k for r in self.model.roads for k in (r, f"{r}_dot") if k in data]
        if not chans or not all(r in roads for r in self.model.roads):
            return None
        if self._excited is None:
            try:
                self._excited = SlidingWindowIdentifier(self.model, self.params, self.config,
                                                        chans)
            except UsageError:
                return None
        _, reason = self._excited.excitation(t, data)
        cols = chans + roads
        if reason or not all(np.isfinite(np.asarray(data[c], dtype=float)).all() for c in cols):
            return None                                  # wait for a fully sampled, excited one
        meas = Measurement(np.asarray(t, dtype=float).copy(),
                           {k: np.asarray(data[k], dtype=float) for k in roads},
                           {c: np.asarray(data[c], dtype=float) for c in chans}, source="window")
        try:
            found = check_offset(OutputErrorProblem(self.model, meas, cost=self.config.cost),
                                 self.params).offset
        except (UsageError, ValueError, np.linalg.LinAlgError):
            return None
        self.checked = True
        if found is None:
            return None
        self.offset = found
        self.t = float(t[-1])
        fields = found.to_json(self.remove)
        fields["offset_kind"] = fields.pop("kind")          # the event's kind is "offset"
        return Notice(self.t, "offset", found.warning(self.model, self.remove), fields)

    def process(self, t: FloatArray, data: Mapping[str, FloatArray]
                ) -> tuple[Mapping[str, FloatArray], Notice | None]:
        """One window: checked while no excited window has been, then corrected; returns the
        window for the estimator (the offset subtracted, unless none was found or it is kept)
        and the ``offset`` notice on the window that found it."""
        notice = None if self.checked else self._check(t, data)
        if self.offset is not None and self.remove:
            out = dict(data)
            for e in self.offset.effects():
                out = e.compensate(t, out)
            return out, notice
        return data, notice

    def summary(self) -> dict[str, Any] | None:
        """The summary's ``offset``: ``None``, or ``t`` (s) and :meth:`Offset.to_json`."""
        if self.offset is None:
            return None
        return {"t": self.t, **self.offset.to_json(self.remove)}
