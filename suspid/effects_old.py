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

import copy
import math
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Any, ClassVar, Iterable, Mapping, Sequence, TypeVar

import numpy as np
# scipy.interpolate (which loads scipy.optimize, ~0.2 s) is reached through scipy's lazy
# submodule attribute, so a monitor that never resamples a channel does not pay for it
import scipy

from suspid.errors import UsageError
from suspid.models.base import GRAVITY, FloatArray, ForceFn, Site, SuspensionModel
from suspid.nlsim import Law, simulate_effects
from suspid.simulate import simulate, simulate_ode

#: velocity scale (m/s) of the smoothed sign in ``coulomb_friction``: ``F tanh(d'/V_EPS)``
V_EPS = 0.01

#: any effect class: ``with_values`` returns the type it is called on
_E = TypeVar("_E", bound="Effect")


# ------------------------------------------------------------------------- parameters
@dataclass(frozen=True)
class EffectParam:
    """One parameter of an effect.

    Attributes
    ----------
    name : str
        Name as in the contract's table.
    unit : str
        SI unit (``"SI"`` for a sensor offset: the channel's own unit).
    description : str
    kind : {"positive", "real", "channel", "channels"}
        ``positive``: a float > 0 (fitted in log coordinates); ``real``: any float;
        ``channel``: one channel name; ``channels``: a list of channel names.
    """

    name: str
    unit: str
    description: str
    kind: str = "positive"


# ------------------------------------------------------------------------- sites
# The models own their struts and tyres (suspid.models.base.Site); these two functions are
# the effects' way to ask for them.
def strut_sites(model: SuspensionModel, p: Mapping[str, float]) -> list[Site]:
    """The suspension struts of ``model`` (deflection = extension, force resists extension)."""
    return model.strut_sites(p)


def tyre_sites(model: SuspensionModel, p: Mapping[str, float]) -> list[Site]:
    """The tyre contacts of ``model`` (coordinate = tyre compression ``r - x_wheel``)."""
    return model.tyre_sites(p)


# ------------------------------------------------------------------------- effects
#: settings of one screening trial of a physical effect (e.g. ``{"gap": 0.01}``)
Trial = dict[str, float]


class Effect:
    """Base class of every effect (see :class:`PhysicalEffect`, :class:`SensorEffect`).

    Parameters
    ----------
    **values
        The effect's parameters by name (see :attr:`params`).

    Raises
    ------
    UsageError
        Unknown or missing parameter, or a value of the wrong kind.
    """

    name: ClassVar[str] = ""
    kind: ClassVar[str] = ""
    params: ClassVar[tuple[EffectParam, ...]] = ()
    description: ClassVar[str] = ""

    def __init__(self, **values: Any) -> None:
        names = [p.name for p in self.params]
        unknown = [k for k in values if k not in names]
        if unknown:
            raise UsageError(f"effect {self.name}: unknown parameter(s) {', '.join(unknown)}; "
                             f"expected {', '.join(names) or 'none'}")
        missing = [k for k in names if k not in values]
        if missing:
            raise UsageError(f"effect {self.name}: missing parameter(s) {', '.join(missing)}")
        self.values: dict[str, Any] = {}
        for spec in self.params:
            self.values[spec.name] = _check_value(self.name, spec, values[spec.name])

    # ---- names and values ---------------------------------------------------------
    @property
    def numeric_names(self) -> list[str]:
        """Names of the float parameters (the ones an optimiser can vary)."""
        return [p.name for p in self.params if p.kind in ("positive", "real")]

    def spec(self, name: str) -> EffectParam:
        """The :class:`EffectParam` called ``name``."""
        for p in self.params:
            if p.name == name:
                return p
        raise UsageError(f"effect {self.name} has no parameter {name!r}")

    def with_values(self: _E, **values: Any) -> _E:
        """A copy with some parameters replaced."""
        v = dict(self.values)
        v.update(values)
        return type(self)(**v)

    def to_json(self) -> dict[str, Any]:
        """``{"name": ..., "params": {...}}`` as the contract prints it."""
        out: dict[str, Any] = {}
        for k, v in self.values.items():
            out[k] = list(v) if isinstance(v, (list, tuple)) else (float(v) if isinstance(v, float) else v)
        return {"name": self.name, "params": out}

    # ---- where it applies -----------------------------------------------------------
    @classmethod
    def unavailable_reason(cls, model: SuspensionModel) -> str | None:
        """Why the effect is not defined for ``model`` (``None``: it is).

        Decided from the model's structure (its sites and channels), never its name.
        """
        return None

    @classmethod
    def limits(cls, model: SuspensionModel) -> dict[str, str]:
        """What the diagnosis cannot identify about this effect with ``model``.

        Returns
        -------
        dict
            ``form -> plain sentence`` (empty when nothing), printed in ``evidence.limits``.
        """
        return {}

    def check_model(self, model: SuspensionModel) -> None:
        """Raise :class:`UsageError` if the effect is not defined for ``model``."""
        why = self.unavailable_reason(model)
        if why is not None:
            raise UsageError(f"effect {self.name} is not available for model {model.name}: {why}")

    def record_problem(self, t: FloatArray) -> str | None:
        """Why the effect cannot act on a record sampled at ``t`` (s); ``None``: it can.

        The base class finds nothing; :class:`SensorDelay` objects to a delay no shorter
        than the record (the delayed channels would hold their first value throughout).
        """
        return None

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.values.items())
        return f"{type(self).__name__}({args})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Effect) and type(self) is type(other) and self.values == other.values


def _check_value(effect: str, spec: EffectParam, value: Any) -> Any:
    if spec.kind == "channels":
        if isinstance(value, str):
            value = [c for c in value.replace("+", " ").replace(";", " ").replace("|", " ").split() if c]
        if not isinstance(value, (list, tuple)) or not value or not all(isinstance(c, str) for c in value):
            raise UsageError(f"effect {effect}: {spec.name}: expected a non-empty list of channel "
                             f"names, got {value!r}")
        return list(value)
    if spec.kind == "channel":
        if not isinstance(value, str) or not value:
            raise UsageError(f"effect {effect}: {spec.name}: expected a channel name, got {value!r}")
        return value
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise UsageError(f"effect {effect}: {spec.name}: expected a number ({spec.unit}), "
                         f"got {value!r}") from None
    if not math.isfinite(v):
        raise UsageError(f"effect {effect}: {spec.name}: expected a finite number, got {value!r}")
    if spec.kind == "positive" and v <= 0:
        raise UsageError(f"effect {effect}: {spec.name}: expected a value > 0 {spec.unit}, got {v}")
    return v


class PhysicalEffect(Effect):
    """An effect in the right-hand side: a scalar force law at every site of one kind.

    Besides the force (:meth:`law`) the class tells the diagnosis how to find it. The
    residual force of the fitted linear model is regressed on the base parameters'
    sensitivities plus, per site, the columns :meth:`regressors` returns (the force per
    unit of each coefficient, times the site's direction ``b``); :meth:`from_coefficients`
    turns the coefficients into the effect's parameters (the refit's start) and says
    whether they are physical. Parameters the force is not linear in are tried on a grid
    (:meth:`screen_trials`, e.g. the bump stop's gap). The refit optimises ``positive``
    parameters in log coordinates and ``real`` ones linearly, from those starting values;
    base parameters the effect replaces are tied to it (:meth:`base_overrides`).
    """

    kind: ClassVar[str] = "physical"
    #: ``"strut"`` or ``"tyre"``
    site_kind: ClassVar[str] = "strut"
    #: what the evidence figure plots the residual force against: ``"rate"`` (``s'``) or
    #: ``"deflection"`` (``s``)
    plot_against: ClassVar[str] = "rate"

    # ---- sites ------------------------------------------------------------------------
    @classmethod
    def model_sites(cls, model: SuspensionModel, p: Mapping[str, float] | None = None) -> list[Site]:
        """Every site of ``model`` of this effect's kind (``p``: parameters, default the model's)."""
        q = model.defaults() if p is None else p
        return strut_sites(model, q) if cls.site_kind == "strut" else tyre_sites(model, q)

    @classmethod
    def sites_problem(cls, sites: Sequence[Site]) -> str | None:
        """Why the effect cannot act at ``sites`` with one parameter set (``None``: it can)."""
        return None if sites else f"the model has no {cls.site_kind}"

    @classmethod
    def unavailable_reason(cls, model: SuspensionModel) -> str | None:
        try:
            sites = cls.model_sites(model)
        except UsageError as exc:
            return str(exc)
        return cls.sites_problem(sites)

    def sites(self, model: SuspensionModel, p: Mapping[str, float]) -> list[Site]:
        """Sites of ``model`` where this effect acts."""
        sites = self.model_sites(model, p)
        why = self.sites_problem(sites)
        if why is not None:
            raise UsageError(f"effect {self.name} is not available for model {model.name}: {why}")
        return sites

    # ---- physics ----------------------------------------------------------------------
    def law(self, site: Site, base: Mapping[str, float]) -> Law:
        """Scalar force law ``phi(s, s') -> N`` at ``site`` for base parameters ``base``."""
        raise NotImplementedError(f"effect {self.name}: no force law")

    def generalized_force(self, model: SuspensionModel, X: FloatArray, U: FloatArray,
                          base: Mapping[str, float]) -> FloatArray:
        """Generalised force rows ``Q`` (N, nq) (N, N m) for state rows ``X`` and inputs ``U``."""
        X2 = np.atleast_2d(np.asarray(X, dtype=float))
        U2 = np.atleast_2d(np.asarray(U, dtype=float))
        Q = np.zeros((X2.shape[0], len(model.coords)))
        for site in self.sites(model, base):
            phi = self.law(site, base)
            s, sd = site.coordinate(X2, U2)
            f = np.fromiter((phi(a, b) for a, b in zip(s.tolist(), sd.tolist())), float, s.size)
            Q += f[:, None] * site.b[None, :]
        return Q

    def force_fn(self, model: SuspensionModel) -> ForceFn:
        """The effect as a ``model.extra_force`` term ``f(t, x, u, params) -> Q``."""
        self.check_model(model)

        def f(t: float, x: FloatArray, u: FloatArray, params: Mapping[str, float]) -> FloatArray:
            return self.generalized_force(model, x, u, params)[0]

        # the term remembers its effect (model.extra_force terms are plain callables)
        f.effect = self  # type: ignore[attr-defined]
        return f

    def base_overrides(self, sites: Sequence[Site]) -> dict[str, float]:
        """Base parameters this effect determines at ``sites`` (name -> value, SI).

        The refit does not fit them separately: they follow the effect's parameters (an
        asymmetric damper's symmetric part is the strut's ``c``). Default: none.

        Raises
        ------
        ValueError
            The sites do not allow one such value (e.g. two different dampers).
        """
        return {}

    # ---- diagnosis --------------------------------------------------------------------
    @classmethod
    def screen_trials(cls, sites: Sequence[Site], s: Sequence[FloatArray],
                      sd: Sequence[FloatArray]) -> list[Trial]:
        """Settings tried when screening (default one trial, ``{}``).

        Parameters
        ----------
        sites : sequence of Site
            Where the effect is screened.
        s, sd : sequence of ndarray
            Each site's coordinate (m) and rate (m/s) over the record (smoothed measured
            motion).

        Returns
        -------
        list of dict
            One dict per trial (passed to :meth:`regressors` and
            :meth:`from_coefficients`); empty: the effect cannot show in this record.
        """
        return [{}]

    @classmethod
    def regressors(cls, site: Site, s: FloatArray, sd: FloatArray, base: Mapping[str, float],
                   trial: Trial, rate_noise: float) -> list[FloatArray]:
        """Force (N) per unit of each coefficient at ``site``: ``phi ~ sum_j beta_j col_j``.

        Parameters
        ----------
        site : Site
        s, sd : ndarray
            Site coordinate (m) and rate (m/s), one value per sample.
        base : mapping
            Base parameters of the fitted linear model (SI).
        trial : dict
            One of :meth:`screen_trials`.
        rate_noise : float
            Standard deviation (m/s) of the white noise left in ``sd``.
        """
        raise NotImplementedError(f"effect {cls.name}: no screening regressors")

    @classmethod
    def from_coefficients(cls, coef: FloatArray, base: Mapping[str, float], trial: Trial,
                          sites: Sequence[Site], rate_noise: Sequence[float]
                          ) -> tuple[dict[str, Any], bool, str]:
        """Effect parameters from the screening coefficients of :meth:`regressors`.

        Returns
        -------
        params : dict
            The effect's parameters (the refit's start).
        plausible : bool
            Whether they are physically possible (e.g. a friction force > 0).
        note : str
            A sentence for the evidence (may be empty).

        The default serves an effect with one numeric parameter and one regressor: the
        coefficient is that parameter, plausible when positive.
        """
        names = [p.name for p in cls.params if p.kind in ("positive", "real")]
        if len(names) != 1 or len(cls.params) != 1:
            raise NotImplementedError(f"effect {cls.name}: no screening coefficients")
        return {names[0]: float(coef[0])}, float(coef[0]) > 0, ""


class SensorEffect(Effect):
    """An effect in the measurement model (what the sensors report).

    For the diagnosis a sensor effect names the channel groups it may affect
    (:meth:`screen_groups`) and its reading's change per unit of its screened parameter
    (:meth:`output_sensitivity`, linearised about no effect); the output residual of each
    group is regressed on that, and :meth:`params_from_screen` turns the coefficient into
    the effect's parameters. An effect that shifts its channels in time (:attr:`time_shift`
    names the delay parameter) is also screened on the residual force with the group's
    motion shifted, and undone by an all-pass shift in the refit.
    """

    kind: ClassVar[str] = "sensor"
    #: name of the parameter (s) by which the effect delays its channels, for a time shift
    time_shift: ClassVar[str | None] = None

    def apply(self, t: FloatArray, channels: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
        """Map true channels (SI) at times ``t`` (s) to what the sensors report."""
        raise NotImplementedError(f"effect {self.name}: no measurement model")

    def compensate(self, t: FloatArray, channels: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
        """Undo the effect on measured channels (NaN where the truth cannot be recovered)."""
        raise NotImplementedError(f"effect {self.name}: no compensation")

    def affected(self) -> list[str]:
        """Channels this effect changes (its ``channels`` or ``channel`` parameter)."""
        names = [p.name for p in self.params if p.kind in ("channels", "channel")]
        out: list[str] = []
        for n in names:
            v = self.values[n]
            out += list(v) if isinstance(v, list) else [v]
        return out

    def check_channels(self, model: SuspensionModel) -> None:
        """Raise :class:`UsageError` if a named channel is not one of the model's."""
        bad = [c for c in self.affected() if c not in model.channels]
        if bad:
            raise UsageError(f"effect {self.name}: unknown channel(s) {', '.join(bad)} for model "
                             f"{model.name}; expected any of {', '.join(model.channels)}")

    # ---- diagnosis --------------------------------------------------------------------
    @classmethod
    def screen_groups(cls, model: SuspensionModel, measured: Sequence[str]) -> list[list[str]]:
        """Channel groups the effect may affect (default: each measured channel alone)."""
        return [[c] for c in measured]

    @classmethod
    def output_sensitivity(cls, channel: str, t: FloatArray,
                           predicted: Mapping[str, FloatArray]) -> FloatArray | None:
        """Change of ``channel``'s reading per unit of the screened parameter (channel units
        per parameter unit), linearised about no effect, from the fitted model's channels
        ``predicted``; ``None`` where it cannot be formed."""
        raise NotImplementedError(f"effect {cls.name}: no output sensitivity")

    @classmethod
    def params_from_screen(cls, group: Sequence[str], value: float,
                           max_delay: float) -> dict[str, Any] | None:
        """The effect's parameters for channel ``group`` and screened value ``value``
        (``None`` when that value is not physical, e.g. a delay outside ``(0, max_delay]``)."""
        raise NotImplementedError(f"effect {cls.name}: no screening parameters")


#: name -> effect class: the built-in ones in the contract's order, then plugins
REGISTRY: dict[str, type[Effect]] = {}
#: entry-point group from which other installed packages add effects (name -> class)
ENTRY_POINT_GROUP = "suspid.effects"
_plugins_loaded = False


def register(cls: type[Effect]) -> type[Effect]:
    """Class decorator adding an effect to :data:`REGISTRY` (its ``name`` must be unique)."""
    if not cls.name or cls.name in REGISTRY:
        raise ValueError(f"effect class {cls.__name__}: empty or duplicate name {cls.name!r}")
    REGISTRY[cls.name] = cls
    return cls


def load_plugins(force: bool = False) -> None:
    """Add the effects other installed packages declare in the entry-point group
    ``suspid.effects`` (``name = "module:Class"``) to :data:`REGISTRY` (once; ``force``
    reads the group again).

    Raises
    ------
    UsageError
        A plugin that cannot be imported, is not an effect class, whose class ``name``
        differs from its entry-point name, that lacks a hook the diagnosis needs, or that
        takes a name already registered by another class. The message names the entry
        point and the package that declares it.
    """
    global _plugins_loaded
    if _plugins_loaded and not force:
        return
    _plugins_loaded = True
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        dist = getattr(getattr(ep, "dist", None), "name", None) or "unknown package"
        where = f"effect plugin {ep.name!r} ({ep.value}, from {dist}, entry point group {ENTRY_POINT_GROUP})"
        try:
            cls = ep.load()
        except Exception as exc:  # noqa: BLE001 - any import failure of foreign code
            raise UsageError(f"{where}: cannot be loaded: {type(exc).__name__}: {exc}") from exc
        _check_plugin(where, ep.name, cls)
        if REGISTRY.get(ep.name, cls) is not cls:
            raise UsageError(f"{where}: the name is already taken by "
                             f"{REGISTRY[ep.name].__module__}.{REGISTRY[ep.name].__qualname__}")
        REGISTRY[ep.name] = cls


def _check_plugin(where: str, name: str, cls: Any) -> None:
    if not (isinstance(cls, type) and issubclass(cls, (PhysicalEffect, SensorEffect))):
        raise UsageError(f"{where}: expected a subclass of suspid.effects.PhysicalEffect "
                         f"or SensorEffect, got {cls!r}")
    if cls.name != name:
        raise UsageError(f"{where}: the class's name is {cls.name!r}, expected {name!r}")
    base: type[Effect] = PhysicalEffect if issubclass(cls, PhysicalEffect) else SensorEffect
    hooks = (("law", "regressors", "from_coefficients") if base is PhysicalEffect else
             ("apply", "compensate", "output_sensitivity", "params_from_screen"))
    missing = [h for h in hooks if next(k for k in cls.__mro__ if h in k.__dict__) is base]
    if missing:
        raise UsageError(f"{where}: {cls.__qualname__} does not implement {', '.join(missing)}")


def effect_classes() -> dict[str, type[Effect]]:
    """Every registered effect class by name (built-ins, then plugins; see :func:`load_plugins`)."""
    load_plugins()
    return REGISTRY


@register
class CoulombFriction(PhysicalEffect):
    """Dry friction in the strut: ``F sgn(d')``, sign smoothed as ``tanh(d'/V_EPS)``.

    Screening: the friction regressor is a sign of the *measured* rate. With noise it flips
    at random while the strut sticks, which shrinks the estimate of ``F``; the expected
    friction given a noisy rate is a softer sign, so it is screened as ``tanh(d'/w)`` with
    ``w = hypot(V_EPS, m 1.2 sigma_rate)`` for ``m`` = 1, 2, 4, 8 (trials); with little
    noise every ``w`` is ``V_EPS``. The refit uses the law.
    """

    name = "coulomb_friction"
    params = (EffectParam("F", "N", "dry friction force in the suspension strut"),)
    description = "dry friction F sgn(d') in the strut"

    def law(self, site: Site, base: Mapping[str, float]) -> Law:
        F = self.values["F"]
        return lambda s, sd: F * math.tanh(sd / V_EPS)

    @staticmethod
    def sign_width(trial: Trial, rate_noise: float) -> float:
        """Velocity scale (m/s) of the screened sign for a trial's ``widen`` factor."""
        return math.hypot(V_EPS, trial.get("widen", 1.0) * 1.2 * rate_noise)

    @classmethod
    def screen_trials(cls, sites: Sequence[Site], s: Sequence[FloatArray],
                      sd: Sequence[FloatArray]) -> list[Trial]:
        return [{"widen": w} for w in (1.0, 2.0, 4.0, 8.0)]

    @classmethod
    def regressors(cls, site: Site, s: FloatArray, sd: FloatArray, base: Mapping[str, float],
                   trial: Trial, rate_noise: float) -> list[FloatArray]:
        return [np.tanh(sd / cls.sign_width(trial, rate_noise))]

    @classmethod
    def from_coefficients(cls, coef: FloatArray, base: Mapping[str, float], trial: Trial,
                          sites: Sequence[Site], rate_noise: Sequence[float]
                          ) -> tuple[dict[str, Any], bool, str]:
        c = float(coef[0])
        width = cls.sign_width(trial, rate_noise[0] if len(rate_noise) else 0.0)
        return {"F": c}, c > 0, f"sign of the strut rate screened as tanh(rate / {width:.3g} m/s)"


@register
class AsymmetricDamping(PhysicalEffect):
    """Damper ``c_rebound d'`` in rebound (``d' > 0``), ``c_compression d'`` in compression.

    It replaces the linear damper ``c1 d'``: the extra force is
    ``(c_rebound - c1) max(d', 0) + (c_compression - c1) min(d', 0)``. The base ``c1`` of an
    augmented fit is reported as the symmetric part ``(c_rebound + c_compression) / 2``.
    Available only where one damper coefficient describes every strut.
    """

    name = "asymmetric_damping"
    params = (EffectParam("c_rebound", "N s/m", "damping in rebound (extension, d' > 0)"),
              EffectParam("c_compression", "N s/m", "damping in compression (d' < 0)"))
    description = "damper c_rebound d' in extension, c_compression d' in compression"

    def law(self, site: Site, base: Mapping[str, float]) -> Law:
        c = base[site.c_name] if site.c_name else 0.0
        dr = self.values["c_rebound"] - c
        dc = self.values["c_compression"] - c
        return lambda s, sd: dr * sd if sd > 0.0 else dc * sd

    @classmethod
    def sites_problem(cls, sites: Sequence[Site]) -> str | None:
        if not sites:
            return "the model has no strut"
        names = [s.c_name for s in sites]
        if None in names or len(set(names)) != 1:
            return ("its two coefficients cannot describe dampers whose symmetric parts "
                    f"{_and(sorted(str(n) for n in set(names)))} differ")
        return None

    @classmethod
    def limits(cls, model: SuspensionModel) -> dict[str, str]:
        try:
            sites = cls.model_sites(model)
        except UsageError:
            return {}
        if len(sites) < 2 or cls.sites_problem(sites) is None:
            return {}
        n = len(sites)
        dampers = _and([str(s.c_name) for s in sites])
        alone = (f"the {' or the '.join(_short(s.name) for s in sites)} strut alone" if n == 2
                 else "one strut alone")
        return {f"asymmetric_damping ({'both' if n == 2 else 'all'} struts)":
                f"one (c_rebound, c_compression) pair cannot describe {_NUMBER.get(n, str(n))} "
                f"dampers whose symmetric parts {dampers} differ, and the contract has no "
                f"per-strut pair; asymmetric damping is tested in {alone}"}

    def base_overrides(self, sites: Sequence[Site]) -> dict[str, float]:
        names = {site.c_name for site in sites}
        if len(names) != 1 or None in names:
            raise ValueError(f"asymmetric_damping needs exactly one damper, got {sorted(map(str, names))}")
        return {str(names.pop()): 0.5 * (self.values["c_rebound"] + self.values["c_compression"])}

    @classmethod
    def regressors(cls, site: Site, s: FloatArray, sd: FloatArray, base: Mapping[str, float],
                   trial: Trial, rate_noise: float) -> list[FloatArray]:
        return [np.abs(sd)]

    @classmethod
    def from_coefficients(cls, coef: FloatArray, base: Mapping[str, float], trial: Trial,
                          sites: Sequence[Site], rate_noise: Sequence[float]
                          ) -> tuple[dict[str, Any], bool, str]:
        # |d'| = max(d', 0) - min(d', 0): the coefficient splits the damper symmetrically
        # about the strut's fitted c
        cbar = base[str(sites[0].c_name)]
        cr, cc = cbar + float(coef[0]), cbar - float(coef[0])
        return {"c_rebound": cr, "c_compression": cc}, cr > 0 and cc > 0, ""


@register
class QuadraticDamping(PhysicalEffect):
    """Extra damper force ``c_quad |d'| d'`` (orifice-type damping)."""

    name = "quadratic_damping"
    params = (EffectParam("c_quad", "N s^2/m^2", "quadratic damping coefficient"),)
    description = "extra damper force c_quad |d'| d'"

    def law(self, site: Site, base: Mapping[str, float]) -> Law:
        cq = self.values["c_quad"]
        return lambda s, sd: cq * abs(sd) * sd

    @classmethod
    def regressors(cls, site: Site, s: FloatArray, sd: FloatArray, base: Mapping[str, float],
                   trial: Trial, rate_noise: float) -> list[FloatArray]:
        return [np.abs(sd) * sd]


@register
class ProgressiveSpring(PhysicalEffect):
    """Spring ``k1 d + k_cubic d^3`` (the cubic term is the effect)."""

    name = "progressive_spring"
    params = (EffectParam("k_cubic", "N/m^3", "cubic stiffness of a progressive spring"),)
    description = "spring force k1 d + k_cubic d^3"
    plot_against = "deflection"

    def law(self, site: Site, base: Mapping[str, float]) -> Law:
        k3 = self.values["k_cubic"]
        return lambda s, sd: k3 * s * s * s

    @classmethod
    def regressors(cls, site: Site, s: FloatArray, sd: FloatArray, base: Mapping[str, float],
                   trial: Trial, rate_noise: float) -> list[FloatArray]:
        return [s ** 3]


@register
class BumpStop(PhysicalEffect):
    """Bump stop: ``k_stop (-d - gap)`` pushes back once the compression exceeds ``gap``.

    Screening: the force is linear in ``k_stop`` for a given ``gap``; gaps from 15 % to
    90 % of the record's largest compression (its 99.5 % quantile, over the screened
    sites) are tried.
    """

    name = "bump_stop"
    params = (EffectParam("gap", "m", "compression from static equilibrium at which the stop engages"),
              EffectParam("k_stop", "N/m", "stiffness of the bump stop"))
    description = "bump stop of stiffness k_stop beyond a compression gap"
    plot_against = "deflection"

    def law(self, site: Site, base: Mapping[str, float]) -> Law:
        gap, ks = self.values["gap"], self.values["k_stop"]
        return lambda s, sd: -ks * (-s - gap) if -s > gap else 0.0

    @classmethod
    def screen_trials(cls, sites: Sequence[Site], s: Sequence[FloatArray],
                      sd: Sequence[FloatArray]) -> list[Trial]:
        comp = np.concatenate([-np.asarray(x) for x in s])
        hi = float(np.quantile(comp, 0.995))
        if hi <= 0:
            return []
        return [{"gap": float(g)} for g in np.linspace(0.15, 0.9, 16) * hi]

    @classmethod
    def regressors(cls, site: Site, s: FloatArray, sd: FloatArray, base: Mapping[str, float],
                   trial: Trial, rate_noise: float) -> list[FloatArray]:
        return [-np.maximum(-s - float(trial["gap"]), 0.0)]

    @classmethod
    def from_coefficients(cls, coef: FloatArray, base: Mapping[str, float], trial: Trial,
                          sites: Sequence[Site], rate_noise: Sequence[float]
                          ) -> tuple[dict[str, Any], bool, str]:
        return {"gap": float(trial.get("gap") or 0.0), "k_stop": float(coef[0])}, float(coef[0]) > 0, ""


@register
class TireLiftoff(PhysicalEffect):
    """The tyre cannot pull: the contact force ``W + k s + c s'`` is clipped at zero."""

    name = "tire_liftoff"
    params = ()
    site_kind = "tyre"
    description = "tyre contact force cannot become negative (wheel leaves the road)"

    def law(self, site: Site, base: Mapping[str, float]) -> Law:
        W = site.load
        k = base[site.k_name] if site.k_name else 0.0
        c = base[site.c_name] if site.c_name else 0.0

        def phi(s: float, sd: float) -> float:
            n = W + k * s + c * sd
            return -n if n < 0.0 else 0.0

        return phi

    @classmethod
    def limits(cls, model: SuspensionModel) -> dict[str, str]:
        # a tyre whose element is also a strut's: no wheel mass between them
        try:
            tyres = cls.model_sites(model)
            struts = strut_sites(model, model.defaults())
        except UsageError:
            return {}
        shared = {s.k_name for s in struts} & {s.k_name for s in tyres} - {None}
        if not shared:
            return {}
        return {"tire_liftoff (wheel hop)":
                f"{model.name} has no wheel: its one spring/damper is suspension and tyre in "
                "series, so tire_liftoff can only mean the whole corner leaving the road "
                "(the element cannot pull the body down); a wheel hopping under a body "
                "still held by its spring is not representable (use quarter2)"}

    @classmethod
    def regressors(cls, site: Site, s: FloatArray, sd: FloatArray, base: Mapping[str, float],
                   trial: Trial, rate_noise: float) -> list[FloatArray]:
        # the pulling force the linear tyre would exert (1 x it if the tyre lifts off)
        k = base[site.k_name] if site.k_name else 0.0
        c = base[site.c_name] if site.c_name else 0.0
        return [np.maximum(-(site.load + k * s + c * sd), 0.0)]

    @classmethod
    def from_coefficients(cls, coef: FloatArray, base: Mapping[str, float], trial: Trial,
                          sites: Sequence[Site], rate_noise: Sequence[float]
                          ) -> tuple[dict[str, Any], bool, str]:
        c = float(coef[0])
        return {}, 0.3 < c < 3.0, f"coefficient of the pulling-force regressor {c:.3g} (1 if the tyre lifts off)"


#: small counts in words
_NUMBER = {2: "two", 3: "three", 4: "four", 5: "five", 6: "six"}


def _short(site_name: str) -> str:
    """``"front strut"`` -> ``"front"``."""
    return site_name.rsplit(" ", 1)[0] if " " in site_name else site_name


def _and(items: Sequence[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    items = list(items)
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def _shift(t: FloatArray, y: FloatArray, dt: float) -> FloatArray:
    """``y(t + dt)`` by cubic-spline interpolation of the valid samples (s, channel units).

    Before the first sample the first value is held; beyond the last the result is NaN.
    """
    ok = ~np.isnan(y)
    if ok.sum() < 4:
        return np.interp(t + dt, t[ok], y[ok], right=np.nan)
    tq = t + dt
    out = scipy.interpolate.CubicSpline(t[ok], y[ok], extrapolate=False)(tq)
    out = np.where(tq < t[ok][0], y[ok][0], out)
    return np.where(tq > t[ok][-1], np.nan, out)


def _rate(ch: str, t: FloatArray, predicted: Mapping[str, FloatArray]) -> FloatArray | None:
    """Time derivative of the model's channel ``ch`` (None if the model lacks it)."""
    if ch.endswith("_ddot"):
        return np.gradient(predicted[ch], t) if ch in predicted else None
    if ch.endswith("_dot"):
        return predicted.get(ch[:-4] + "_ddot")
    return predicted.get(f"{ch}_dot")


@register
class SensorDelay(SensorEffect):
    """The listed channels lag the others by ``delay_s``: they read ``y(t - delay_s)``.

    Screening: groups are the measured channels of one coordinate together and each alone;
    a lag ``d`` changes a reading by ``-d y'`` (linearised).
    """

    name = "sensor_delay"
    params = (EffectParam("channels", "", "channels that lag", "channels"),
              EffectParam("delay_s", "s", "delay of the listed channels"))
    description = "listed channels lag the others by delay_s"
    time_shift = "delay_s"

    def apply(self, t: FloatArray, channels: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
        out = dict(channels)
        tt = np.asarray(t, dtype=float)
        for c in self.values["channels"]:
            if c in out:
                out[c] = _shift(tt, np.asarray(out[c], dtype=float), -self.values["delay_s"])
        return out

    def compensate(self, t: FloatArray, channels: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
        out = dict(channels)
        tt = np.asarray(t, dtype=float)
        for c in self.values["channels"]:
            if c in out:
                out[c] = _shift(tt, np.asarray(out[c], dtype=float), self.values["delay_s"])
        return out

    def record_problem(self, t: FloatArray) -> str | None:
        tt = np.asarray(t, dtype=float)
        span = float(tt[-1] - tt[0]) if tt.size > 1 else 0.0
        d = float(self.values["delay_s"])
        if d >= span:
            return (f"delay_s {d:g} s is not shorter than the record ({span:g} s): the delayed "
                    "channels would hold their first value throughout (a delay in ms? give it in s)")
        return None

    @classmethod
    def screen_groups(cls, model: SuspensionModel, measured: Sequence[str]) -> list[list[str]]:
        groups: list[list[str]] = []
        for c in model.coords:
            g = [ch for ch in (c, f"{c}_dot", f"{c}_ddot") if ch in measured]
            if g:
                groups.append(g)
                groups += [[ch] for ch in g] if len(g) > 1 else []
        return groups

    @classmethod
    def output_sensitivity(cls, channel: str, t: FloatArray,
                           predicted: Mapping[str, FloatArray]) -> FloatArray | None:
        r = _rate(channel, t, predicted)
        return None if r is None else -np.asarray(r, dtype=float)

    @classmethod
    def params_from_screen(cls, group: Sequence[str], value: float,
                           max_delay: float) -> dict[str, Any] | None:
        if not 0.0 < value <= max_delay:
            return None
        return {"channels": list(group), "delay_s": value}


@register
class SensorOffset(SensorEffect):
    """``channel`` reads ``y + offset`` (SI units of the channel)."""

    name = "sensor_offset"
    params = (EffectParam("channel", "", "channel with the offset", "channel"),
              EffectParam("offset", "SI", "constant offset added to the channel", "real"))
    description = "constant offset on one channel"

    def apply(self, t: FloatArray, channels: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
        out = dict(channels)
        c = self.values["channel"]
        if c in out:
            out[c] = np.asarray(out[c], dtype=float) + self.values["offset"]
        return out

    def compensate(self, t: FloatArray, channels: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
        out = dict(channels)
        c = self.values["channel"]
        if c in out:
            out[c] = np.asarray(out[c], dtype=float) - self.values["offset"]
        return out

    @classmethod
    def output_sensitivity(cls, channel: str, t: FloatArray,
                           predicted: Mapping[str, FloatArray]) -> FloatArray | None:
        return np.ones(np.asarray(t).size)

    @classmethod
    def params_from_screen(cls, group: Sequence[str], value: float,
                           max_delay: float) -> dict[str, Any] | None:
        return {"channel": group[0], "offset": value} if len(group) == 1 else None


#: effect names of the contract's table, in its order (built-ins only)
EFFECT_NAMES: tuple[str, ...] = tuple(REGISTRY)


# ------------------------------------------------------------------------- construction
def make_effect(name: str, **values: Any) -> Effect:
    """Build the effect called ``name`` with parameters ``values``.

    Raises
    ------
    UsageError
        Unknown effect (lists the known ones) or bad parameters.
    """
    reg = effect_classes()
    try:
        cls = reg[name]
    except KeyError:
        raise UsageError(f"unknown effect {name!r}; expected one of {', '.join(reg)}") from None
    return cls(**values)


def parse_effect(spec: str) -> Effect:
    """Parse ``"NAME"`` or ``"NAME:key=value,key=value"`` into an effect.

    Lists (``sensor_delay``'s ``channels``) separate their items with ``+``, e.g.
    ``sensor_delay:channels=x1+x1_dot,delay_s=0.01``.
    """
    name, _, rest = spec.strip().partition(":")
    values: dict[str, Any] = {}
    for item in (s for s in rest.split(",") if s.strip()):
        k, sep, v = item.partition("=")
        if not sep or not k.strip():
            raise UsageError(f"effect {spec!r}: expected NAME:key=value,..., got item {item!r}")
        values[k.strip()] = v.strip()
    return make_effect(name.strip(), **values)


def as_effect(e: "Effect | str | Mapping[str, Any]") -> Effect:
    """Accept an :class:`Effect`, a spec string or ``{"name": ..., "params": {...}}``."""
    if isinstance(e, Effect):
        return e
    if isinstance(e, str):
        return parse_effect(e)
    if isinstance(e, Mapping) and "name" in e:
        return make_effect(str(e["name"]), **dict(e.get("params", {})))
    raise UsageError(f"expected an effect, a 'NAME:key=value' string or a {{'name', 'params'}} "
                     f"mapping, got {e!r}")


# ------------------------------------------------------------------------- injection
@dataclass
class Injection:
    """A model with effects nobody declared to the estimator.

    Attributes
    ----------
    model : SuspensionModel
        Copy of the base model whose ``extra_force`` carries the physical effects (so
        ``model.rhs`` and :func:`suspid.simulate.simulate_ode` include them).
    base : SuspensionModel
        The model without effects.
    effects : tuple of Effect
        Every injected effect, physical and sensor.
    """

    model: SuspensionModel
    base: SuspensionModel
    effects: tuple[Effect, ...]

    @property
    def physical(self) -> list[PhysicalEffect]:
        """The physical effects (right-hand side)."""
        return [e for e in self.effects if isinstance(e, PhysicalEffect)]

    @property
    def sensor(self) -> list[SensorEffect]:
        """The sensor effects (measurement model), in the order they are applied."""
        return [e for e in self.effects if isinstance(e, SensorEffect)]

    def measure(self, t: FloatArray, channels: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
        """Apply the sensor effects to true channels (dict channel -> array, SI) at times ``t`` (s)."""
        out = dict(channels)
        for e in self.sensor:
            out = e.apply(t, out)
        return out

    def simulate(self, params: Mapping[str, float], t: FloatArray,
                 road: Mapping[str, FloatArray] | None = None, x0: FloatArray | None = None,
                 method: str = "fast", max_step: float = 2.5e-4) -> dict[str, FloatArray]:
        """Simulate the model with every effect and return what the sensors report.

        Parameters
        ----------
        params : mapping
            Base model parameters (SI); the effects carry their own.
        t : ndarray
            Sample times (s).
        road : dict, optional
            Road arrays (m, m/s) as for :func:`suspid.simulate.simulate`.
        x0 : ndarray, optional
            Initial state (default rest).
        method : {"fast", "ode"}
            ``fast``: the exponential integrator of :mod:`suspid.nlsim` with
            internal steps of at most ``max_step`` (s); ``ode``: :func:`simulate_ode`
            (solve_ivp, slow, reference accuracy). Without physical effects the exact linear
            simulator is used either way.
        max_step : float
            Largest internal step of the fast path (s).

        Returns
        -------
        dict
            Channel -> array (positions, ``_dot``, ``_ddot``, roads), sensor effects applied.
        """
        t = np.asarray(t, dtype=float)
        p = dict(params)
        if not self.physical:
            out = simulate(self.base, p, t, road, x0)
        elif method == "ode":
            out = simulate_ode(self.model, p, t, road, x0)
        elif method == "fast":
            h = float(np.min(np.diff(t))) if t.size > 1 else max_step
            sub = max(1, int(math.ceil(h / max_step - 1e-9)))
            out = simulate_effects(self.base, p, self.physical, t, road, x0, substeps=sub)
        else:
            raise UsageError(f"unknown simulation method {method!r}; expected 'fast' or 'ode'")
        return self.measure(t, out)

    def describe(self) -> list[dict[str, Any]]:
        """The injected effects as contract-style ``{"name", "params"}`` objects."""
        return [e.to_json() for e in self.effects]

    def check_record(self, t: FloatArray) -> None:
        """Raise :class:`UsageError` if an effect cannot act on a record sampled at ``t`` (s)."""
        for e in self.effects:
            why = e.record_problem(t)
            if why is not None:
                raise UsageError(f"effect {e.name}: {why}")

    def influence(self, params: Mapping[str, float], t: FloatArray,
                  road: Mapping[str, FloatArray] | None = None, x0: FloatArray | None = None,
                  combined: Mapping[str, FloatArray] | None = None) -> list[float]:
        """How much each effect alone changes what the sensors report (1, relative).

        Parameters
        ----------
        params, t, road, x0
            As for :meth:`simulate`.
        combined : dict, optional
            :meth:`simulate`'s output with every effect, reused when there is one effect.

        Returns
        -------
        list of float
            Per effect, in order: the largest over the model's channels of the RMS change
            the effect makes divided by the channel's RMS without it (0: the record never
            engages it, e.g. a bump stop beyond the largest deflection).
        """
        t = np.asarray(t, dtype=float)
        base = simulate(self.base, dict(params), t, road, x0)
        out: list[float] = []
        for e in self.effects:
            alone = (combined if combined is not None and len(self.effects) == 1
                     else inject(self.base, [e]).simulate(params, t, road, x0))
            worst = 0.0
            for c in self.base.channels:
                if c not in base or c not in alone:
                    continue
                ref = np.asarray(base[c], dtype=float)
                diff = np.asarray(alone[c], dtype=float) - ref
                ok = np.isfinite(diff)
                if not ok.any():
                    continue
                scale = float(np.sqrt(np.mean(ref[ok] ** 2)))
                change = float(np.sqrt(np.mean(diff[ok] ** 2)))
                if scale > 0.0:
                    worst = max(worst, change / scale)
                elif change > 0.0:
                    worst = math.inf
            out.append(worst)
        return out


def inject(model: SuspensionModel,
           effects: Iterable["Effect | str | Mapping[str, Any]"]) -> Injection:
    """Add effects to ``model`` without declaring them to the estimator.

    Parameters
    ----------
    model : SuspensionModel
        The declared (linear) model; it is not modified.
    effects : iterable
        :class:`Effect` instances, spec strings ``"NAME:key=value,..."`` (see
        :func:`parse_effect`) or ``{"name": ..., "params": {...}}`` mappings.

    Returns
    -------
    Injection
        ``.model`` (a copy whose ``rhs`` has the physical terms), ``.measure(t, channels)``
        for the sensor terms and ``.simulate(params, t, road, x0)`` for both.

    Raises
    ------
    UsageError
        Unknown effect, bad parameters, an effect not defined for the model, or a sensor
        effect naming a channel the model does not have.
    """
    effs = tuple(as_effect(e) for e in effects)
    aug = copy.copy(model)
    aug.extra_force = list(model.extra_force)
    for e in effs:
        e.check_model(model)
        if isinstance(e, PhysicalEffect):
            aug.extra_force.append(e.force_fn(aug))
        elif isinstance(e, SensorEffect):
            e.check_channels(model)
    return Injection(model=aug, base=model, effects=effs)


def effects_for(model: SuspensionModel, kinds: Sequence[str] = ("physical", "sensor")) -> list[str]:
    """Names of the registered effects (plugins included) available for ``model``.

    An effect is available when the model has what it needs (:meth:`Effect.unavailable_reason`:
    struts for a strut effect, tyres for a tyre effect, one damper coefficient for every
    strut for ``asymmetric_damping``), whatever the model is called.
    """
    return [n for n, c in effect_classes().items()
            if c.kind in kinds and c.unavailable_reason(model) is None]


__all__ = ["Effect", "EffectParam", "PhysicalEffect", "SensorEffect", "Site", "REGISTRY",
           "EFFECT_NAMES", "ENTRY_POINT_GROUP", "Trial", "register", "load_plugins",
           "effect_classes", "make_effect", "parse_effect", "as_effect", "inject", "Injection",
           "strut_sites", "tyre_sites", "effects_for", "GRAVITY", "V_EPS"]
