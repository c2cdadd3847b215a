"""``qcar5``: a quarter car whose tyre is a pure spring (five parameters).

    m1 x1'' + c1 (x1' - x2') + k1 (x1 - x2) = 0
    m2 x2'' + c1 (x2' - x1') + k1 (x2 - x1) = -k2 (x2 - r)

Same sensors and CAN messages as ``quarter2`` (body ``x1``, wheel ``x2``, road ``r``; the
quarter-car sensor set), a different parameterisation: no tyre damping to identify.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from suspid.models.base import GRAVITY, DoeDesign, ParamSpec, Site, SuspensionModel


class QCar5(SuspensionModel):
    """Body ``m1`` on the suspension (``k1``, ``c1``) over wheel ``m2`` on an undamped tyre ``k2``."""

    sensor_set = 1
    alert_id = 1
    known = ("m1", "m2")
    #: ``suspid doe --model qcar5``: the seed's L27-3 array as quarter2 uses it, without
    #: the tyre damper's factor J (qcar5 has none)
    doe_design = DoeDesign("L27-3", {"A": "x1", "B": "x1_dot", "C": "x2", "D": "x2_dot",
                                     "E": "m1", "F": "c1", "G": "k1", "H": "m2", "K": "k2"})

    def __init__(self) -> None:
        super().__init__(
            name="qcar5",
            coords=("x1", "x2"),
            roads=("r",),
            params=(
                ParamSpec("m1", "kg", 300.0, "mass", "sprung (body) mass of one corner"),
                ParamSpec("c1", "N s/m", 1500.0, "damping", "suspension damping"),
                ParamSpec("k1", "N/m", 20000.0, "stiffness", "suspension spring stiffness"),
                ParamSpec("m2", "kg", 40.0, "mass", "unsprung (wheel) mass"),
                ParamSpec("k2", "N/m", 200000.0, "stiffness", "tyre vertical stiffness"),
            ),
            scale_invariant=("m1", "c1", "k1", "m2", "k2"),
        )

    def matrices(self, p: Mapping[str, float]) -> tuple[np.ndarray, ...]:
        m1, c1, k1, m2, k2 = (p[n] for n in ("m1", "c1", "k1", "m2", "k2"))
        M = np.array([[m1, 0.0], [0.0, m2]])
        C = np.array([[c1, -c1], [-c1, c1]])
        K = np.array([[k1, -k1], [-k1, k1 + k2]])
        Fk = np.array([[0.0], [k2]])
        Fc = np.array([[0.0], [0.0]])
        return M, C, K, Fk, Fc

    def initial_state(self) -> np.ndarray:
        """Body 5 cm up and moving, wheel at rest (a visible free response)."""
        return np.array([0.05, 0.0, 0.2, 0.0])

    def strut_sites(self, p: Mapping[str, float]) -> list[Site]:
        g = np.array([1.0, -1.0])
        return [Site("strut", "strut", g, np.zeros(1), -g, "c1", "k1")]

    def tyre_sites(self, p: Mapping[str, float]) -> list[Site]:
        g = np.array([0.0, -1.0])
        return [Site("tyre", "tyre", g, np.array([1.0]), -g, None, "k2",
                     (p["m1"] + p["m2"]) * GRAVITY)]
