"""Result of an identification run (in the style of lmfit's MinimizerResult)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class IdentResult:
    """Outcome of :func:`estimator.identify.fit`.

    Attributes
    ----------
    model : str
    params : dict
        Every parameter (fixed ones included), SI units.
    fixed : list of str
    stderr : dict
        Standard error of each free parameter (SI), sandwich estimate.
    cost : float
        The seed's cost at the optimum (``sse`` or ``frobenius``), SI.
    nfev : int
        Cost evaluations, all restarts included.
    success : bool
        Converged and identifiable.
    rms_residual : dict
        RMS residual per measured channel (SI).
    identifiable : bool
    warnings : list of str
    x0 : list of float
        Initial state used.
    aic, bic : float
        Information criteria of the normalised least-squares fit.
    starts : list of dict, optional
        Per start: ``start`` (``"data"``, ``"init"``, ...), ``from``, ``cost``, ``params``
        and ``chosen``.
    data_start : dict, optional
        The data-driven estimate (``values``, ``bandwidth_hz``) or ``reason``.
    bands : dict, optional
        ``name -> (lo, hi)``: the 3-sigma band (SI; :mod:`estimator.identify.profile`),
        ``inf`` for a side the record does not bound.
    band_method : dict, optional
        ``name -> "curvature"`` or ``"profile"``.
    offset : dict, optional
        A constant offset found (:mod:`estimator.identify.offset`): ``kind``, ``values``
        (SI), ``removed``, ``share`` and ``effects``.
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
