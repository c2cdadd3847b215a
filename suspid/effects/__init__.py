"""Effect library: optional terms the linear suspension models lack.

Every entry of the contract's ``suspid diagnose`` table is one registered class:

===================== ============================== =========================================
name                  parameters                     term
===================== ============================== =========================================
coulomb_friction      ``F`` (N)                      strut force ``F sgn(d')``
asymmetric_damping    ``c_rebound``, ``c_compression`` damper ``c_rebound d'`` for ``d' > 0``
                      (N s/m)                        (rebound = extension), ``c_compression d'``
                                                     for ``d' < 0``; replaces ``c1 d'``
quadratic_damping     ``c_quad`` (N s^2/m^2)         strut force ``c_quad |d'| d'``
progressive_spring    ``k_cubic`` (N/m^3)            spring ``k1 d + k_cubic d^3``
bump_stop             ``gap`` (m), ``k_stop`` (N/m)  ``k_stop (-d - gap)`` once the compression
                                                     ``-d`` exceeds ``gap``
tire_liftoff          (none)                         the tyre cannot pull: contact force
                                                     ``W + k2 s + c2 s' >= 0``
sensor_delay          ``channels`` (list),           listed channels read ``y(t - delay_s)``
                      ``delay_s`` (s)
sensor_offset         ``channel``, ``offset`` (SI)   ``channel`` reads ``y + offset``
===================== ============================== =========================================

Each class carries everything about its effect: the law (the force, or what the sensor
reports), where it applies (from the model's structure), and what ``suspid diagnose``
needs to find it in a residual and refit it (regressors, screening trials, starting
values, the base parameters it replaces, how its fitted values are plotted). The
diagnosis (:mod:`estimator.diagnose`) is generic over the registry.

Conventions
-----------
* The suspension (strut) deflection is the *extension* ``d`` (m): ``x1 - x2`` for
  ``quarter2``, ``x - y`` for ``quarter1`` (the single strut stands on the road), and
  ``x - x1 - a1 delta`` (front) / ``x - x2 + a2 delta`` (rear) for ``half4``. ``d' > 0`` is
  rebound (extension), ``d' < 0`` compression. Positions are measured from static
  equilibrium, as in the linear models.
* A *physical* effect adds a scalar force ``phi(s, s')`` at one or more *sites* (struts or
  tyres, :func:`strut_sites` / :func:`tyre_sites`); its generalised force is
  ``Q = b * phi`` with the site's direction ``b``. For a strut ``phi`` is the extra force
  resisting extension and ``b = -dd/dq``. The force enters the one right-hand side
  through :attr:`SuspensionModel.extra_force` (:meth:`PhysicalEffect.force_fn`), so
  :func:`suspid.simulate.simulate_ode` and the fast simulator :mod:`suspid.nlsim`
  integrate the same physics.
* A *sensor* effect acts in the measurement model only: :meth:`SensorEffect.apply` maps true
  channels to what the sensor reports, :meth:`SensorEffect.compensate` undoes it on data.
* ``tire_liftoff`` needs the static wheel load ``W`` (N) of each tyre site (``(m1 + m2) g``
  for ``quarter2``, the axle loads for ``half4``), ``g = 9.81 m/s^2``. Tyre compression is
  ``s = r - x_w``.

Where an effect applies
-----------------------
Availability follows the model's structure, never its name
(:meth:`Effect.unavailable_reason`, :func:`effects_for`):

* a strut effect applies to every model with struts, a tyre effect to every model with
  tyres; a physical effect acts at *every* site of its kind with one parameter set (the
  same hardware at every corner);
* ``asymmetric_damping`` replaces the linear damper, so it applies only where *one* damper
  coefficient describes every strut (``quarter1``'s ``c``, ``quarter2``'s ``c1``); with
  several dampers (``half4``'s ``c1`` and ``c2``) its two coefficients cannot describe
  dampers whose symmetric parts differ (the diagnosis tests it in one strut alone);
* a sensor effect applies to every model; its channels must be the model's.

Undeclared effects (data generation)
------------------------------------
:func:`inject` is the entry point for tests, demos and the sensor-node firmware::

    from suspid.models import get_model
    from suspid.effects import inject

    inj = inject(get_model("quarter2"), ["coulomb_friction:F=120",
                                         "sensor_offset:channel=x1,offset=0.004"])
    out = inj.simulate(params, t, road, x0)   # every channel, effects included
    # or step by step: inj.model.rhs(t, x, u, params) has the physical terms, and
    # inj.measure(t, channels) applies the sensor terms to simulated channels.

Adding an effect
----------------
One class decorated with :func:`register` (or, from another installed package, named in
the entry-point group ``suspid.effects``: ``NAME = "package.module:Class"``, loaded into
the registry on first use, :func:`load_plugins`). A physical effect names its parameters
and ``site_kind`` and implements :meth:`PhysicalEffect.law` (the force),
:meth:`PhysicalEffect.regressors` and :meth:`PhysicalEffect.from_coefficients` (how the
diagnosis screens the residual force for it and reads its starting values), optionally
:meth:`PhysicalEffect.screen_trials` (nonlinear parameters tried on a grid, as the bump
stop's gap), :meth:`PhysicalEffect.base_overrides` (base parameters it replaces) and
:attr:`PhysicalEffect.plot_against`. A sensor effect implements
:meth:`SensorEffect.apply` / :meth:`SensorEffect.compensate` and the screening hooks
:meth:`SensorEffect.screen_groups`, :meth:`SensorEffect.output_sensitivity` and
:meth:`SensorEffect.params_from_screen`. See ``docs/architecture.md``.
"""
from __future__ import annotations

from suspid.effects.base import (ENTRY_POINT_GROUP, REGISTRY, Effect, EffectParam, PhysicalEffect,
                                 SensorEffect, Site, Trial, effect_classes, load_plugins, register,
                                 strut_sites, tyre_sites)
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
           "strut_sites", "tyre_sites", "effects_for", "GRAVITY", "V_EPS", "CoulombFriction",
           "AsymmetricDamping", "QuadraticDamping", "ProgressiveSpring", "BumpStop",
           "TireLiftoff", "SensorDelay", "SensorOffset", "Law"]
