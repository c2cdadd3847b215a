"""7-DOF full car: body heave, pitch and roll over four wheels.

Coordinates ``q = [x, delta, phi, x1, x2, x3, x4]``: body heave (m), pitch (rad, the ``half4``
sign), roll (rad, positive when the left side rises) and the wheels (m) at the corners 1
front-left, 2 front-right, 3 rear-left, 4 rear-right.

Corner ``i`` at ``l_i`` (front ``-a1``, rear ``+a2``) and ``y_i`` (left ``+w/2``, right
``-w/2``) has the strut extension ``d_i = x + l_i delta + y_i phi - x_i`` (spring ``ki``,
damper ``ci``); wheel ``mi`` stands on the tyre spring ``kti`` over road ``ri``. The centre
of mass is at mid-track.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from suspid.models.base import GRAVITY, DoeDesign, FloatArray, Matrices, ParamSpec, Site, SuspensionModel

#: corner labels in coordinate order
CORNERS = ("front-left", "front-right", "rear-left", "rear-right")


# The full car's design of experiments (the seed has none): Table 5's L27-3 on the left side
# of the car; FULL7_CHOICES says what and why.

#: Table 5 column -> full7 initial-state name or parameter (the left side of the car)
FULL7_COLUMNS: dict[str, str] = {"A": "x1", "B": "x1_dot", "C": "x3", "D": "x3_dot",
                                 "E": "m1", "F": "c1", "G": "k1", "H": "m3", "J": "c3", "K": "k3"}

#: values every row shares (SI): body, geometry, the right corners at Table 5's middle
#: level, tyres as the half car's targets k3 (front) and k4 (rear)
FULL7_CONSTANTS: dict[str, float] = {
    "m": 400.0, "Iy": 80.0, "Ix": 50.0,
    "a1": 0.48, "a2": 0.52, "w1": 1.0, "w2": 1.0,
    "m2": 31.62, "c2": 316.23, "k2": 316.23,
    "m4": 79.06, "c4": 158.11, "k4": 158.11,
    "kt1": 1000.0, "kt2": 1000.0, "kt3": 500.0, "kt4": 500.0,
}

#: body initial state: the half car's 0.05 in heave, pitch and their rates, and in roll
FULL7_BODY_X0: dict[str, float] = {"x": 0.05, "delta": 0.05, "phi": 0.05,
                                   "x_dot": 0.05, "delta_dot": 0.05, "phi_dot": 0.05}

#: what the design chooses, and why (for ``suspid doe --json``'s ``setup``)
FULL7_CHOICES: dict[str, str] = {
    "column_mapping": "Table 5 on the left side: E,F,G = front-left m1, c1, k1; H,J,K = "
                      "rear-left m3, c3, k3; A-D = front-left (x1) and rear-left (x3) wheel "
                      "initial position and velocity",
    "right_corners": "Table 5's middle level (m2 = 31.62 kg, c2 = k2 = 316.23; m4 = 79.06 kg, "
                     "c4 = k4 = 158.11): left-right asymmetric rows couple roll to heave",
    "m, Iy": "400 kg, 80 kg m^2: twice the half car's body (dynamic index 0.80)",
    "Ix": "50 kg m^2: roll radius of gyration 0.35 m on a 1 m track",
    "tyres": "kt1 = kt2 = 1000 N/m, kt3 = kt4 = 500 N/m (the half car's k3, k4)",
    "body_initial_state": "0.05 in heave, pitch, roll and their rates",
}


class Full7(SuspensionModel):
    """Full car: heave, pitch and roll of the body over four wheels."""

    sensor_set = 3
    angles = ("delta", "phi")
    alert_id = 3
    known = ("m", "Ix", "Iy", "m1", "m2", "m3", "m4", "a1", "a2", "w1", "w2")
    doe_design = DoeDesign("L27-3", FULL7_COLUMNS, FULL7_CONSTANTS, FULL7_BODY_X0, FULL7_CHOICES)

    def __init__(self) -> None:
        corner = [("front-left", 1900.0, 28000.0), ("front-right", 1900.0, 28000.0),
                  ("rear-left", 1600.0, 24000.0), ("rear-right", 1600.0, 24000.0)]
        params = [ParamSpec("m", "kg", 1400.0, "mass", "body (sprung) mass"),
                  ParamSpec("Ix", "kg m^2", 450.0, "inertia", "body roll moment of inertia"),
                  ParamSpec("Iy", "kg m^2", 2000.0, "inertia", "body pitch moment of inertia")]
        params += [ParamSpec(f"m{i}", "kg", 40.0, "mass", f"{c} unsprung mass")
                   for i, (c, _, _) in enumerate(corner, 1)]
        params += [ParamSpec(f"c{i}", "N s/m", cv, "damping", f"{c} suspension damping")
                   for i, (c, cv, _) in enumerate(corner, 1)]
        params += [ParamSpec(f"k{i}", "N/m", kv, "stiffness", f"{c} suspension stiffness")
                   for i, (c, _, kv) in enumerate(corner, 1)]
        params += [ParamSpec(f"kt{i}", "N/m", 200000.0, "stiffness", f"{c} tyre stiffness")
                   for i, (c, _, _) in enumerate(corner, 1)]
        params += [ParamSpec("a1", "m", 1.2, "length", "centre of mass to front axle"),
                   ParamSpec("a2", "m", 1.4, "length", "centre of mass to rear axle"),
                   ParamSpec("w1", "m", 1.55, "length", "front track width"),
                   ParamSpec("w2", "m", 1.55, "length", "rear track width")]
        super().__init__(
            name="full7",
            coords=("x", "delta", "phi", "x1", "x2", "x3", "x4"),
            roads=("r1", "r2", "r3", "r4"),
            params=tuple(params),
            scale_invariant=tuple(s.name for s in params if s.kind != "length"),
        )

    def strut_directions(self, p: Mapping[str, float]) -> FloatArray:
        """Rows ``g_i`` (4, 7): strut extension ``d_i = g_i . q`` per corner (longitudinal
        position ``l_i``, lateral ``y_i``, m)."""
        a1, a2, w1, w2 = p["a1"], p["a2"], p["w1"], p["w2"]
        G = np.zeros((4, 7))
        G[:, 0] = 1.0
        G[:, 1] = np.array([-a1, -a1, a2, a2])
        G[:, 2] = np.array([w1 / 2, -w1 / 2, w2 / 2, -w2 / 2])
        G[:, 3:] = -np.eye(4)
        return G

    def matrices(self, p: Mapping[str, float]) -> Matrices:
        G = self.strut_directions(p)
        c = np.array([p[f"c{i}"] for i in range(1, 5)])
        k = np.array([p[f"k{i}"] for i in range(1, 5)])
        kt = np.array([p[f"kt{i}"] for i in range(1, 5)])
        C = G.T @ (c[:, None] * G)
        K = G.T @ (k[:, None] * G)
        K[3:, 3:] += np.diag(kt)
        M = np.diag([p["m"], p["Iy"], p["Ix"], p["m1"], p["m2"], p["m3"], p["m4"]])
        Fk = np.zeros((7, 4))
        Fk[3:, :] = np.diag(kt)
        Fc = np.zeros((7, 4))
        return M, C, K, Fk, Fc

    def initial_state(self) -> FloatArray:
        """Body released from x = 0.05 m, delta = 0.05 rad, phi = 0.03 rad, rates 0.05 /s."""
        x0 = np.zeros(14)
        x0[[0, 1, 2]] = [0.05, 0.05, 0.03]
        x0[[7, 8, 9]] = [0.05, 0.05, 0.05]
        return x0

    def road_tracks(self) -> tuple[int, ...]:
        """``r1``, ``r3`` on the left track (0); ``r2``, ``r4`` on the right (1)."""
        return (0, 1, 0, 1)

    def road_lags(self, p: Mapping[str, float]) -> tuple[float, ...]:
        """The rear tyres run the wheelbase ``a1 + a2`` (m) behind the front ones."""
        L = p["a1"] + p["a2"]
        return (0.0, 0.0, L, L)

    def strut_sites(self, p: Mapping[str, float]) -> list[Site]:
        G = self.strut_directions(p)
        return [Site(f"{name} strut", "strut", G[i], np.zeros(4), -G[i], f"c{i + 1}", f"k{i + 1}")
                for i, name in enumerate(CORNERS)]

    def tyre_sites(self, p: Mapping[str, float]) -> list[Site]:
        """Four tyres; static corner loads with the centre of mass at mid-track (N)."""
        a1, a2, m = p["a1"], p["a2"], p["m"]
        body = [m * a2 / (2 * (a1 + a2))] * 2 + [m * a1 / (2 * (a1 + a2))] * 2
        out = []
        for i, name in enumerate(CORNERS):
            g = np.zeros(7)
            g[3 + i] = -1.0
            gr = np.zeros(4)
            gr[i] = 1.0
            out.append(Site(f"{name} tyre", "tyre", g, gr, -g, None, f"kt{i + 1}",
                            (body[i] + p[f"m{i + 1}"]) * GRAVITY))
        return out
