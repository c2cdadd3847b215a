"""1-DOF quarter car, seed eq. (1): m x'' + c (x' - y') + k (x - y) = 0."""
from __future__ import annotations

from typing import Mapping

import numpy as np

from suspid.models.base import FloatArray, ParamSpec, SuspensionModel


class Quarter1(SuspensionModel):
    """One mass ``m`` on a spring ``k`` and damper ``c`` over the road ``y``."""

    def __init__(self) -> None:
        super().__init__(
            name="quarter1",
            coords=("x",),
            roads=("y",),
            params=(
                ParamSpec("m", "kg", 300.0, "mass", "quarter-car sprung mass"),
                ParamSpec("c", "N s/m", 1500.0, "damping", "damping coefficient"),
                ParamSpec("k", "N/m", 20000.0, "stiffness", "spring stiffness"),
            ),
            scale_invariant=("m", "c", "k"),
        )

    def matrices(self, p: Mapping[str, float]) -> tuple[FloatArray, ...]:
        m, c, k = p["m"], p["c"], p["k"]
        return (np.array([[m]]), np.array([[c]]), np.array([[k]]),
                np.array([[k]]), np.array([[c]]))
