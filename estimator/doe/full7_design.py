"""A design for the full car (``full7``), the half car's L27-3 carried over to four corners.

The seed has no full-car design. This one reuses Table 5's L27-3 array and levels with the
half car's reading (:data:`estimator.doe.design.HALF4_COLUMNS`) on the *left* side of the
car: E, F, G (``m1``, ``c1``, ``k1``) are the front-left wheel mass, damper and spring; H,
J, K (``m3``, ``c3``, ``k3``) the rear-left ones; A-D the initial position and velocity of
the front-left (``x1``) and rear-left (``x3``) wheels. The right corners keep Table 5's
middle level (so every row is left-right asymmetric, which couples roll to heave and pitch
and lets each corner be told apart), the tyres the half car's ``k3``/``k4`` values, and the
body twice the half car's mass and pitch inertia. Every free parameter of
:func:`estimator.doe.runner.free_names` (all but the masses and inertias: 12 dampers and
springs and the four lengths) is identified.

This module only defines the design; :mod:`estimator.doe.runner` registers it next to the
seed's designs. It is self-contained so it can move next to the model with the others.
"""
from __future__ import annotations

from estimator.doe.arrays import L27_ARRAY, L27_LEVELS
from estimator.doe.design import DesignSpec

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

#: the design
FULL7_DESIGN = DesignSpec("L27-3", L27_ARRAY, L27_LEVELS, FULL7_COLUMNS, FULL7_CONSTANTS,
                          FULL7_BODY_X0, FULL7_CHOICES)
