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

Conventions
-----------
* The suspension (strut) deflection is the *extension* ``d`` (m): ``x1 - x2`` for
  ``quarter2``, ``x - y`` for ``quarter1`` (the single strut stands on the road), and
  ``x - x1 - a1 delta`` (front) / ``x - x2 + a2 delta`` (rear) for ``half4``. ``d' > 0`` is
  rebound (extension), ``d' < 0`` compression. Positions are measured from static
  equilibrium, as in the linear models.
* A *physical* effect adds a scalar force ``phi(s, s')`` at one or more *sites* (struts or
  tyres); its generalised force is ``Q = b * phi`` with the site's direction ``b``. For a
  strut ``phi`` is the extra force resisting extension and ``b = -dd/dq``. The force enters
  the one right-hand side through :attr:`SuspensionModel.extra_force`
  (:meth:`PhysicalEffect.force_fn`), so :func:`suspid.simulate.simulate_ode` and the fast
  simulator :mod:`estimator.diagnose.nlsim` integrate the same physics.
* A *sensor* effect acts in the measurement model only: :meth:`SensorEffect.apply` maps true
  channels to what the sensor reports, :meth:`SensorEffect.compensate` undoes it on data.
* ``tire_liftoff`` needs the static wheel load ``W`` (N): ``(m1 + m2) g`` for ``quarter2``,
  ``m g`` for ``quarter1`` (whose strut is also the road contact), and the axle loads
  ``(m a2/(a1 + a2) + m1) g`` / ``(m a1/(a1 + a2) + m2) g`` for ``half4``, with
  ``g = 9.81 m/s^2``. Tyre compression is ``s = r - x_w``.

Model coverage
--------------
* ``quarter2``: every effect.
* ``quarter1``: every effect; the strut is the spring/damper ``k``, ``c`` between the mass and
  the road, and ``tire_liftoff`` means that element cannot pull the mass down.
* ``half4``: strut effects act on *both* struts with the same parameters (same hardware
  front and rear); ``tire_liftoff`` acts on both tyres. ``asymmetric_damping`` is not
  offered for ``half4``: its two coefficients cannot describe two dampers whose symmetric
  parts ``c1`` and ``c2`` differ.

Undeclared effects (data generation)
------------------------------------
:func:`inject` is the entry point for tests, demos and the sensor-node firmware::

    from suspid.models import get_model
    from suspid.models.effects import inject

    inj = inject(get_model("quarter2"), ["coulomb_friction:F=120",
                                         "sensor_offset:channel=x1,offset=0.004"])
    out = inj.simulate(params, t, road, x0)   # every channel, effects included
    # or step by step: inj.model.rhs(t, x, u, params) has the physical terms, and
    # inj.measure(t, channels) applies the sensor terms to simulated channels.

Adding an effect is one class decorated with :func:`register` that names its parameters
and implements :meth:`PhysicalEffect.law` (or the two sensor methods).
"""
from __future__ import annotations

import copy
import math
from abc import abstractmethod
from dataclasses import dataclass
from typing import Any, Callable, ClassVar, Iterable, Mapping, Sequence

import numpy as np

from suspid.errors import UsageError
from suspid.models.base import GRAVITY, FloatArray, ForceFn, Site, SuspensionModel

#: velocity scale (m/s) of the smoothed sign in ``coulomb_friction``: ``F tanh(d'/V_EPS)``
V_EPS = 0.01

#: scalar law of a physical effect at one site: ``phi(s, s_dot) -> force`` (N)
Law = Callable[[float, float], float]


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
    models: ClassVar[tuple[str, ...]] = ("quarter1", "quarter2", "half4")
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

    def with_values(self, **values: Any) -> "Effect":
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

    def check_model(self, model: SuspensionModel) -> None:
        """Raise :class:`UsageError` if the effect is not defined for ``model``."""
        if model.name not in self.models:
            raise UsageError(f"effect {self.name} is not available for model {model.name}; "
                             f"it is defined for {', '.join(self.models)}")

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.values.items())
        return f"{type(self).__name__}({args})"

    def __eq__(self, other: object) -> bool:
        return type(self) is type(other) and self.values == other.values  # type: ignore[attr-defined]


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
    """An effect in the right-hand side: a scalar force law at every site of one kind."""

    kind: ClassVar[str] = "physical"
    #: ``"strut"`` or ``"tyre"``
    site_kind: ClassVar[str] = "strut"

    def sites(self, model: SuspensionModel, p: Mapping[str, float]) -> list[Site]:
        """Sites of ``model`` where this effect acts."""
        self.check_model(model)
        return strut_sites(model, p) if self.site_kind == "strut" else tyre_sites(model, p)

    @abstractmethod
    def law(self, site: Site, base: Mapping[str, float]) -> Law:
        """Scalar force law ``phi(s, s') -> N`` at ``site`` for base parameters ``base``."""

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

        f.effect = self  # type: ignore[attr-defined]
        return f


class SensorEffect(Effect):
    """An effect in the measurement model (what the sensors report)."""

    kind: ClassVar[str] = "sensor"

    @abstractmethod
    def apply(self, t: FloatArray, channels: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
        """Map true channels (SI) at times ``t`` (s) to what the sensors report."""

    @abstractmethod
    def compensate(self, t: FloatArray, channels: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
        """Undo the effect on measured channels (NaN where the truth cannot be recovered)."""

    def affected(self) -> list[str]:
        """Channels this effect changes."""
        v = self.values.get("channels", self.values.get("channel"))
        return list(v) if isinstance(v, list) else [v]

    def check_channels(self, model: SuspensionModel) -> None:
        """Raise :class:`UsageError` if a named channel is not one of the model's."""
        bad = [c for c in self.affected() if c not in model.channels]
        if bad:
            raise UsageError(f"effect {self.name}: unknown channel(s) {', '.join(bad)} for model "
                             f"{model.name}; expected any of {', '.join(model.channels)}")


#: name -> effect class, in the contract's order
REGISTRY: dict[str, type[Effect]] = {}


def register(cls: type[Effect]) -> type[Effect]:
    """Class decorator adding an effect to :data:`REGISTRY` (its ``name`` must be unique)."""
    if not cls.name or cls.name in REGISTRY:
        raise ValueError(f"effect class {cls.__name__}: empty or duplicate name {cls.name!r}")
    REGISTRY[cls.name] = cls
    return cls


@register
class CoulombFriction(PhysicalEffect):
    """Dry friction in the strut: ``F sgn(d')``, sign smoothed as ``tanh(d'/V_EPS)``."""

    name = "coulomb_friction"
    params = (EffectParam("F", "N", "dry friction force in the suspension strut"),)
    description = "dry friction F sgn(d') in the strut"

    def law(self, site: Site, base: Mapping[str, float]) -> Law:
        F = self.values["F"]
        return lambda s, sd: F * math.tanh(sd / V_EPS)


@register
class AsymmetricDamping(PhysicalEffect):
    """Damper ``c_rebound d'`` in rebound (``d' > 0``), ``c_compression d'`` in compression.

    It replaces the linear damper ``c1 d'``: the extra force is
    ``(c_rebound - c1) max(d', 0) + (c_compression - c1) min(d', 0)``. The base ``c1`` of an
    augmented fit is reported as the symmetric part ``(c_rebound + c_compression) / 2``.
    """

    name = "asymmetric_damping"
    params = (EffectParam("c_rebound", "N s/m", "damping in rebound (extension, d' > 0)"),
              EffectParam("c_compression", "N s/m", "damping in compression (d' < 0)"))
    models = ("quarter1", "quarter2")
    description = "damper c_rebound d' in extension, c_compression d' in compression"

    def law(self, site: Site, base: Mapping[str, float]) -> Law:
        c = base[site.c_name] if site.c_name else 0.0
        dr = self.values["c_rebound"] - c
        dc = self.values["c_compression"] - c
        return lambda s, sd: dr * sd if sd > 0.0 else dc * sd


@register
class QuadraticDamping(PhysicalEffect):
    """Extra damper force ``c_quad |d'| d'`` (orifice-type damping)."""

    name = "quadratic_damping"
    params = (EffectParam("c_quad", "N s^2/m^2", "quadratic damping coefficient"),)
    description = "extra damper force c_quad |d'| d'"

    def law(self, site: Site, base: Mapping[str, float]) -> Law:
        cq = self.values["c_quad"]
        return lambda s, sd: cq * abs(sd) * sd


@register
class ProgressiveSpring(PhysicalEffect):
    """Spring ``k1 d + k_cubic d^3`` (the cubic term is the effect)."""

    name = "progressive_spring"
    params = (EffectParam("k_cubic", "N/m^3", "cubic stiffness of a progressive spring"),)
    description = "spring force k1 d + k_cubic d^3"

    def law(self, site: Site, base: Mapping[str, float]) -> Law:
        k3 = self.values["k_cubic"]
        return lambda s, sd: k3 * s * s * s


@register
class BumpStop(PhysicalEffect):
    """Bump stop: ``k_stop (-d - gap)`` pushes back once the compression exceeds ``gap``."""

    name = "bump_stop"
    params = (EffectParam("gap", "m", "compression from static equilibrium at which the stop engages"),
              EffectParam("k_stop", "N/m", "stiffness of the bump stop"))
    description = "bump stop of stiffness k_stop beyond a compression gap"

    def law(self, site: Site, base: Mapping[str, float]) -> Law:
        gap, ks = self.values["gap"], self.values["k_stop"]
        return lambda s, sd: -ks * (-s - gap) if -s > gap else 0.0


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


def _shift(t: FloatArray, y: FloatArray, dt: float) -> FloatArray:
    """``y(t + dt)`` by cubic-spline interpolation of the valid samples (s, channel units).

    Before the first sample the first value is held; beyond the last the result is NaN.
    """
    from scipy.interpolate import CubicSpline

    ok = ~np.isnan(y)
    if ok.sum() < 4:
        return np.interp(t + dt, t[ok], y[ok], right=np.nan)
    tq = t + dt
    out = CubicSpline(t[ok], y[ok], extrapolate=False)(tq)
    out = np.where(tq < t[ok][0], y[ok][0], out)
    return np.where(tq > t[ok][-1], np.nan, out)


@register
class SensorDelay(SensorEffect):
    """The listed channels lag the others by ``delay_s``: they read ``y(t - delay_s)``."""

    name = "sensor_delay"
    params = (EffectParam("channels", "", "channels that lag", "channels"),
              EffectParam("delay_s", "s", "delay of the listed channels"))
    description = "listed channels lag the others by delay_s"

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


#: effect names in the contract's order
EFFECT_NAMES: tuple[str, ...] = tuple(REGISTRY)


# ------------------------------------------------------------------------- construction
def make_effect(name: str, **values: Any) -> Effect:
    """Build the effect called ``name`` with parameters ``values``.

    Raises
    ------
    UsageError
        Unknown effect (lists the known ones) or bad parameters.
    """
    try:
        cls = REGISTRY[name]
    except KeyError:
        raise UsageError(f"unknown effect {name!r}; expected one of {', '.join(REGISTRY)}") from None
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
            ``fast``: the exponential integrator of :mod:`estimator.diagnose.nlsim` with
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
        from suspid.simulate import simulate, simulate_ode

        t = np.asarray(t, dtype=float)
        p = dict(params)
        if not self.physical:
            out = simulate(self.base, p, t, road, x0)
        elif method == "ode":
            out = simulate_ode(self.model, p, t, road, x0)
        elif method == "fast":
            from estimator.diagnose.nlsim import simulate_effects

            h = float(np.min(np.diff(t))) if t.size > 1 else max_step
            sub = max(1, int(math.ceil(h / max_step - 1e-9)))
            out = simulate_effects(self.base, p, self.physical, t, road, x0, substeps=sub)
        else:
            raise UsageError(f"unknown simulation method {method!r}; expected 'fast' or 'ode'")
        return self.measure(t, out)

    def describe(self) -> list[dict[str, Any]]:
        """The injected effects as contract-style ``{"name", "params"}`` objects."""
        return [e.to_json() for e in self.effects]


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
    """Names of the registered effects available for ``model`` (of the given kinds)."""
    return [n for n, c in REGISTRY.items() if model.name in c.models and c.kind in kinds]


__all__ = ["Effect", "EffectParam", "PhysicalEffect", "SensorEffect", "Site", "REGISTRY",
           "EFFECT_NAMES", "register", "make_effect", "parse_effect", "as_effect", "inject",
           "Injection", "strut_sites", "tyre_sites", "effects_for", "GRAVITY", "V_EPS"]
