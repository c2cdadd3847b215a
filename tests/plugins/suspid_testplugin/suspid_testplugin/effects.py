"""``rebound_stop``: a top-out spring that stops the strut's extension beyond a gap.

The strut extension ``d`` (m) beyond ``gap`` meets a stop of stiffness ``k_top`` (N/m): an
extra force ``k_top (d - gap)`` resisting extension for ``d > gap``, none below. It is the
mirror image of the built-in ``bump_stop`` and none of the built-in laws.

Everything ``suspid diagnose`` needs is here: the law, where it acts (every strut), how the
residual force is screened for it (the force is linear in ``k_top`` for a given gap; gaps
from 15 % to 90 % of the record's largest extension are tried), its starting values and
how it is plotted.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from suspid.effects import EffectParam, Law, PhysicalEffect, Site, Trial


class ReboundStop(PhysicalEffect):
    """Rebound (top-out) stop: ``k_top (d - gap)`` once the extension ``d`` exceeds ``gap``."""

    name = "rebound_stop"
    params = (EffectParam("gap", "m", "extension from static equilibrium at which the stop engages"),
              EffectParam("k_top", "N/m", "stiffness of the rebound stop"))
    description = "rebound stop of stiffness k_top beyond an extension gap"
    site_kind = "strut"
    plot_against = "deflection"

    def law(self, site: Site, base: Mapping[str, float]) -> Law:
        gap, k = self.values["gap"], self.values["k_top"]
        return lambda s, sd: k * (s - gap) if s > gap else 0.0

    @classmethod
    def screen_trials(cls, sites: Sequence[Site], s: Sequence[np.ndarray],
                      sd: Sequence[np.ndarray]) -> list[Trial]:
        ext = np.concatenate([np.asarray(x) for x in s])
        hi = float(np.quantile(ext, 0.995))
        if hi <= 0:
            return []
        return [{"gap": float(g)} for g in np.linspace(0.15, 0.9, 16) * hi]

    @classmethod
    def regressors(cls, site: Site, s: np.ndarray, sd: np.ndarray, base: Mapping[str, float],
                   trial: Trial, rate_noise: float) -> list[np.ndarray]:
        return [np.maximum(s - trial["gap"], 0.0)]

    @classmethod
    def from_coefficients(cls, coef: np.ndarray, base: Mapping[str, float], trial: Trial,
                          sites: Sequence[Site], rate_noise: Sequence[float]
                          ) -> tuple[dict[str, Any], bool, str]:
        k = float(coef[0])
        return {"gap": float(trial["gap"]), "k_top": k}, k > 0, ""
