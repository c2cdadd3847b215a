"""4-DOF half car (bicycle model), seed eqs. (4)-(7).

Coordinates ``q = [x, delta, x1, x2]``: body heave (m), pitch (rad; the body at the front
axle moves by ``x - a1 delta``), front and rear wheels (m). Suspensions ``k1``, ``c1`` at
``a1`` ahead of the centre of mass and ``k2``, ``c2`` at ``a2`` behind; tyres ``k3``, ``k4``
(the suspension deflections ``x - x1 - a1 delta`` and ``x - x2 + a2 delta``).
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from suspid.models.base import (GRAVITY, DoeDesign, FloatArray, Matrices, ParamSpec, Site,
                                SuspensionModel)


#: seed section 6.1 half-car constants (targets, identified) and the choices for m, I
DOE_CONSTANTS: dict[str, float] = {"a1": 0.48, "a2": 0.52, "k3": 1000.0, "k4": 500.0,
                                   "m": 200.0, "I": 40.0}
#: seed section 6.1 body initial state [x (m), delta (rad), x' (m/s), delta' (rad/s)]
DOE_BODY_X0: dict[str, float] = {"x": 0.05, "delta": 0.05, "x_dot": 0.05, "delta_dot": 0.05}
#: what the seed leaves out of its half-car design, and why
DOE_CHOICES: dict[str, str] = {
    "column_mapping": "Table 5 by name: E,F,G = front wheel mass m1, front damper c1, "
                      "front spring k1; H,J,K = rear m2, c2, k2; A-D = front/rear wheel "
                      "initial position and velocity",
    "m": "200 kg: two corners at Table 5's top sprung-mass level (100 kg each)",
    "I": "40 kg m^2: dynamic index I/(m a1 a2) = 0.80 (typical car; 1 would make "
         "front and rear dynamically independent)",
    "horizon_s": "20 s: >= 2/3 of the slowest period of every design row",
    "sample_rate_hz": "100 Hz: resolves the fastest decay (~42 1/s) over several samples",
}


class Half4(SuspensionModel):
    """Body heave and pitch over a front and a rear wheel (``r2`` follows ``r1`` by ``a1 + a2``)."""

    sensor_set = 2
    angles = ("delta",)
    alert_id = 2
    known = ("m", "I", "m1", "m2", "a1", "a2")
    #: the seed's section 6.1 half car (Table 5 by name; DOE_CHOICES says what the seed leaves out)
    doe_design = DoeDesign("L27-3", {"A": "x1", "B": "x1_dot", "C": "x2", "D": "x2_dot",
                                     "E": "m1", "F": "c1", "G": "k1", "H": "m2", "J": "c2",
                                     "K": "k2"},
                           DOE_CONSTANTS, DOE_BODY_X0, DOE_CHOICES)

    def __init__(self) -> None:
        super().__init__(
            name="half4",
            coords=("x", "delta", "x1", "x2"),
            roads=("r1", "r2"),
            params=(
                ParamSpec("m", "kg", 1200.0, "mass", "body (sprung) mass of the half car"),
                ParamSpec("I", "kg m^2", 1500.0, "inertia", "body pitch moment of inertia"),
                ParamSpec("m1", "kg", 40.0, "mass", "front unsprung mass"),
                ParamSpec("m2", "kg", 40.0, "mass", "rear unsprung mass"),
                ParamSpec("c1", "N s/m", 2000.0, "damping", "front suspension damping"),
                ParamSpec("c2", "N s/m", 2000.0, "damping", "rear suspension damping"),
                ParamSpec("k1", "N/m", 30000.0, "stiffness", "front suspension stiffness"),
                ParamSpec("k2", "N/m", 30000.0, "stiffness", "rear suspension stiffness"),
                ParamSpec("k3", "N/m", 200000.0, "stiffness", "front tyre stiffness"),
                ParamSpec("k4", "N/m", 200000.0, "stiffness", "rear tyre stiffness"),
                ParamSpec("a1", "m", 1.2, "length", "centre of mass to front axle"),
                ParamSpec("a2", "m", 1.4, "length", "centre of mass to rear axle"),
            ),
            scale_invariant=("m", "I", "m1", "m2", "c1", "c2", "k1", "k2", "k3", "k4"),
        )

    def matrices(self, p: Mapping[str, float]) -> Matrices:
        m, I, m1, m2 = p["m"], p["I"], p["m1"], p["m2"]
        c1, c2, k1, k2, k3, k4 = p["c1"], p["c2"], p["k1"], p["k2"], p["k3"], p["k4"]
        a1, a2 = p["a1"], p["a2"]
        # suspension deflections: d1 = x - x1 - a1*delta, d2 = x - x2 + a2*delta
        g1 = np.array([1.0, -a1, -1.0, 0.0])
        g2 = np.array([1.0, a2, 0.0, -1.0])
        C = c1 * np.outer(g1, g1) + c2 * np.outer(g2, g2)
        K = k1 * np.outer(g1, g1) + k2 * np.outer(g2, g2)
        K[2, 2] += k3
        K[3, 3] += k4
        M = np.diag([m, I, m1, m2])
        Fk = np.array([[0.0, 0.0], [0.0, 0.0], [k3, 0.0], [0.0, k4]])
        Fc = np.zeros((4, 2))
        return M, C, K, Fk, Fc

    def initial_state(self) -> FloatArray:
        """The seed's section 6.1 body state: x = 0.05 m, delta = 0.05 rad, both rates 0.05 /s."""
        x0 = np.zeros(8)
        x0[[0, 1, 4, 5]] = 0.05
        return x0

    def road_lags(self, p: Mapping[str, float]) -> tuple[float, ...]:
        """The rear tyre runs the wheelbase ``a1 + a2`` (m) behind the front one."""
        return (0.0, p["a1"] + p["a2"])

    def strut_sites(self, p: Mapping[str, float]) -> list[Site]:
        a1, a2 = p["a1"], p["a2"]
        g1 = np.array([1.0, -a1, -1.0, 0.0])
        g2 = np.array([1.0, a2, 0.0, -1.0])
        return [Site("front strut", "strut", g1, np.zeros(2), -g1, "c1", "k1"),
                Site("rear strut", "strut", g2, np.zeros(2), -g2, "c2", "k2")]

    def tyre_sites(self, p: Mapping[str, float]) -> list[Site]:
        """Front and rear tyres; static axle loads ``(m a2/(a1+a2) + m1) g``, ``(m a1/(a1+a2) + m2) g``."""
        a1, a2, m = p["a1"], p["a2"], p["m"]
        wf = (m * a2 / (a1 + a2) + p["m1"]) * GRAVITY
        wr = (m * a1 / (a1 + a2) + p["m2"]) * GRAVITY
        g1 = np.array([0.0, 0.0, -1.0, 0.0])
        g2 = np.array([0.0, 0.0, 0.0, -1.0])
        return [Site("front tyre", "tyre", g1, np.array([1.0, 0.0]), -g1, None, "k3", wf),
                Site("rear tyre", "tyre", g2, np.array([0.0, 1.0]), -g2, None, "k4", wr)]
