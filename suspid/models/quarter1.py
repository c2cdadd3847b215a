"""1-DOF quarter car, seed eq. (1): m x'' + c (x' - y') + k (x - y) = 0."""
from __future__ import annotations

from typing import Mapping

import numpy as np

from suspid.models.base import (GRAVITY, DoeDesign, FloatArray, Matrices, ParamSpec, Site,
                                SuspensionModel)


class Quarter1(SuspensionModel):
    """One mass ``m`` on a spring ``k`` and damper ``c`` over the road ``y``; the one strut is
    also the tyre contact (extension ``x - y``, static load ``m g``)."""

    sensor_set = 1
    angles = ()
    known = ("m",)
    alert_id = 0
    #: the seed's L16-4 design (Tables 3-4): initial position and velocity, m, c, k
    doe_design = DoeDesign("L16-4", {"A": "x", "B": "x_dot", "C": "m", "D": "c", "E": "k"})

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

    def matrices(self, p: Mapping[str, float]) -> Matrices:
        m, c, k = p["m"], p["c"], p["k"]
        return (np.array([[m]]), np.array([[c]]), np.array([[k]]),
                np.array([[k]]), np.array([[c]]))

    def initial_state(self) -> FloatArray:
        """The seed's initial state: x0 = 0.20 m, v0 = 0.50 m/s."""
        return np.array([0.20, 0.50])

    def strut_sites(self, p: Mapping[str, float]) -> list[Site]:
        g, gr = np.array([1.0]), np.array([-1.0])
        return [Site("strut", "strut", g, gr, -g, "c", "k")]

    def tyre_sites(self, p: Mapping[str, float]) -> list[Site]:
        g = np.array([-1.0])
        return [Site("tyre", "tyre", g, np.array([1.0]), -g, "c", "k", p["m"] * GRAVITY)]
