"""Result of an identification run (in the style of lmfit's MinimizerResult)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class IdentResult:
    """Outcome of :func:`estimator.identify.fit` (SI units throughout).

    Every parameter (fixed ones included) and the names held fixed; the sandwich standard
    error of each free one; the seed's cost at the optimum (``sse`` or ``frobenius``); cost
    evaluations over all restarts; ``success`` (converged and identifiable); the RMS
    residual per measured channel; the initial state used; AIC and BIC of the normalised
    least-squares fit. Optional: ``starts`` (per start: ``start``, ``from``, ``cost``,
    ``params``, ``chosen``), ``data_start`` (the data-driven estimate or ``reason``),
    ``bands`` (``name -> (lo, hi)``, the 3-sigma band, ``inf`` for a side the record does
    not bound; :mod:`estimator.identify.profile`) with ``band_method`` (``"curvature"`` or
    ``"profile"``), and ``offset`` (:mod:`estimator.identify.offset`).
    """

    model: str
    params: dict[str, float]
    fixed: list[str]
    stderr: dict[str, float]
    cost: float
    nfev: int
    success: bool
    rms_residual: dict[str, float]
    identifiable: bool
    warnings: list[str] = field(default_factory=list)
    x0: list[float] = field(default_factory=list)
    aic: float = float("nan")
    bic: float = float("nan")
    n_obs: int = 0
    restarts: int = 0
    singular_values: list[float] = field(default_factory=list)
    cov_log: Any = None  # covariance of log-parameters (free ones), ndarray
    frames: dict[str, Any] | None = None
    starts: list[dict[str, Any]] | None = None
    data_start: dict[str, Any] | None = None
    bands: dict[str, tuple[float, float]] | None = None
    band_method: dict[str, str] | None = None
    offset: dict[str, Any] | None = None
    road: str = "measured"
    undetermined: list[str] | None = None
    band_hz: list[float] | None = None
    #: road unknown: body rows whose equation error is clearly more than noise,
    #: ``coordinate -> [noise-floor ratio, share of the signal]``
    misfit: dict[str, list[float]] | None = None

    def to_json(self) -> dict[str, Any]:
        """The contract's JSON object."""
        def f(x: float) -> float | None:
            return float(x) if np.isfinite(x) else None

        out: dict[str, Any] = {
            "model": self.model,
            "params": {k: float(v) for k, v in self.params.items()},
            "fixed": list(self.fixed),
            "cost": f(self.cost),
            "nfev": int(self.nfev),
            "success": bool(self.success),
            "rms_residual": {k: f(v) for k, v in self.rms_residual.items()},
            "stderr": {k: f(v) for k, v in self.stderr.items()},
            "identifiable": bool(self.identifiable),
            "warnings": list(self.warnings),
            "x0": [float(v) for v in self.x0],
            "aic": f(self.aic),
            "bic": f(self.bic),
            "n_obs": int(self.n_obs),
            "restarts": int(self.restarts),
            "road": self.road,
        }
        if self.undetermined is not None:
            out["undetermined"] = list(self.undetermined)
        if self.band_hz is not None:
            out["band_hz"] = list(self.band_hz)
        if self.misfit is not None:
            out["misfit"] = {k: [float(x) for x in v] for k, v in self.misfit.items()}
        if self.frames is not None:
            out["frames"] = self.frames
        if self.starts is not None:
            out["starts"] = self.starts
        if self.data_start is not None:
            out["data_start"] = self.data_start
        if self.bands is not None:
            out["band_3sigma"] = {k: [f(lo), f(hi)] for k, (lo, hi) in self.bands.items()}
            out["band_method"] = dict(self.band_method or {})
        if self.offset is not None:
            out["offset"] = self.offset
        return out
