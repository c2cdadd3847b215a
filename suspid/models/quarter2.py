"""2-DOF quarter car, seed eqs. (2)-(3).

    m1 x1'' + c1 (x1' - x2') + k1 (x1 - x2) = 0
    m2 x2'' + c1 (x2' - x1') + k1 (x2 - x1) = -c2 (x2' - r') - k2 (x2 - r)
"""
from __future__ import annotations

from typing import Collection, Mapping

import numpy as np

from suspid.models.base import (GRAVITY, DoeDesign, FloatArray, Matrices, ParamSpec, Site,
                                SuspensionModel, Twin)


class Quarter2(SuspensionModel):
    """Body ``m1`` on the suspension (``k1``, ``c1``) over wheel ``m2`` on the tyre (``k2``, ``c2``)."""

    sensor_set = 1
    angles = ()
    known = ("m1", "m2")
    alert_id = 1
    #: the seed's L27-3 design (Tables 5-6): body and wheel initial states, then
    #: m1, c1, k1 (body, suspension) and m2, c2, k2 (wheel, tyre)
    doe_design = DoeDesign("L27-3", {"A": "x1", "B": "x1_dot", "C": "x2", "D": "x2_dot",
                                     "E": "m1", "F": "c1", "G": "k1", "H": "m2", "J": "c2",
                                     "K": "k2"})

    def __init__(self) -> None:
        super().__init__(
            name="quarter2",
            coords=("x1", "x2"),
            roads=("r",),
            params=(
                ParamSpec("m1", "kg", 300.0, "mass", "sprung (body) mass of one corner"),
                ParamSpec("c1", "N s/m", 1500.0, "damping", "suspension damping"),
                ParamSpec("k1", "N/m", 20000.0, "stiffness", "suspension spring stiffness"),
                ParamSpec("m2", "kg", 40.0, "mass", "unsprung (wheel) mass"),
                ParamSpec("c2", "N s/m", 300.0, "damping", "tyre damping"),
                ParamSpec("k2", "N/m", 200000.0, "stiffness", "tyre vertical stiffness"),
            ),
            scale_invariant=("m1", "c1", "k1", "m2", "c2", "k2"),
        )

    def matrices(self, p: Mapping[str, float]) -> Matrices:
        m1, c1, k1, m2, c2, k2 = (p[n] for n in ("m1", "c1", "k1", "m2", "c2", "k2"))
        M = np.array([[m1, 0.0], [0.0, m2]])
        C = np.array([[c1, -c1], [-c1, c1 + c2]])
        K = np.array([[k1, -k1], [-k1, k1 + k2]])
        Fk = np.array([[0.0], [k2]])
        Fc = np.array([[0.0], [c2]])
        return M, C, K, Fk, Fc

    def initial_state(self) -> FloatArray:
        """The seed's Table 2: x01 = 0.20 m, x02 = 0.10 m, v01 = 0.50 m/s, v02 = 0.05 m/s."""
        return np.array([0.20, 0.10, 0.50, 0.05])

    def strut_sites(self, p: Mapping[str, float]) -> list[Site]:
        g = np.array([1.0, -1.0])
        return [Site("strut", "strut", g, np.zeros(1), -g, "c1", "k1")]

    def tyre_sites(self, p: Mapping[str, float]) -> list[Site]:
        g = np.array([0.0, -1.0])
        return [Site("tyre", "tyre", g, np.array([1.0]), -g, "c2", "k2",
                     (p["m1"] + p["m2"]) * GRAVITY)]

    def twin(self, p: Mapping[str, float], measured: Collection[str]) -> Twin | None:
        """The suspension and the tyre swapped, when only the body ``x1`` is measured.

        With ``A = c1 s + k1``, ``B = c2 s + k2``, ``M = m1 + m2``, the body's response
        ``x1 / r = A B / (m1 m2 s^4 + s^2 (M A + m1 B) + A B)`` is unchanged by
        ``A' = m1 B / M``, ``B' = M A / m1``. The rule: ``k2 / k1`` the larger (road vehicles
        have about 5-15).
        """
        if "x2" in measured or "x1" not in measured:
            return None
        m1, m2 = p["m1"], p["m2"]
        f = (m1 + m2) / m1
        q = dict(p)
        q.update(c1=p["c2"] / f, k1=p["k2"] / f, c2=p["c1"] * f, k2=p["k1"] * f)
        return Twin(q, "the suspension (c1, k1) and the tyre (c2, k2), scaled by "
                       "(m1 + m2)/m1, from the body alone",
                    "the tyre spring the stiffer one relative to the suspension spring "
                    "(k2/k1 the larger)",
                    q["k2"] * p["k1"] > p["k2"] * q["k1"])
