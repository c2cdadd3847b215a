"""Effect library: optional terms the linear suspension models lack, one registered class per
entry of the contract's ``suspid diagnose`` table: its law, where it applies (from the model's
structure: :func:`effects_for`) and what ``suspid diagnose`` needs to find and refit it.
:func:`inject` adds undeclared effects to a simulation. Adding an effect (a class with
:func:`register`, or an entry point in ``suspid.effects``): ``docs/architecture.md``.
"""
from __future__ import annotations

from suspid.effects.base import (ENTRY_POINT_GROUP, REGISTRY, Effect, EffectParam, PhysicalEffect,
                                 SensorEffect, Site, Trial, effect_classes, load_plugins, register)
from suspid.models.base import GRAVITY
from suspid.nlsim import Law

# isort: split
# the built-in effects register in the contract's order: the physical ones, then the sensor ones
from suspid.effects.strut import (V_EPS, AsymmetricDamping, BumpStop, CoulombFriction,
                                  ProgressiveSpring, QuadraticDamping, TireLiftoff)

# isort: split
from suspid.effects.sensor import SensorDelay, SensorOffset

# isort: split
from suspid.effects.injection import (Injection, as_effect, effects_for, inject, make_effect,
                                      parse_effect)

#: effect names of the contract's table, in its order (built-ins only)
EFFECT_NAMES: tuple[str, ...] = tuple(REGISTRY)

__all__ = ["Effect", "EffectParam", "PhysicalEffect", "SensorEffect", "Site", "REGISTRY",
           "EFFECT_NAMES", "ENTRY_POINT_GROUP", "Trial", "register", "load_plugins",
           "effect_classes", "make_effect", "parse_effect", "as_effect", "inject", "Injection",
           "effects_for", "GRAVITY", "V_EPS", "CoulombFriction",
           "AsymmetricDamping", "QuadraticDamping", "ProgressiveSpring", "BumpStop",
           "TireLiftoff", "SensorDelay", "SensorOffset", "Law"]
