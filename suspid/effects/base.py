"""The effect library's base: effect parameters, the physical and sensor effect classes and
the registry (built-ins and entry-point plugins); see :mod:`suspid.effects`.
"""

import math
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Any, ClassVar, Mapping, Sequence, TypeVar

import numpy as np

from suspid.errors import UsageError
from suspid.models.base import FloatArray, ForceFn, Site, SuspensionModel
from suspid.nlsim import Law

#: any effect class: ``with_values`` returns the type it is called on
_E = TypeVar("_E", bound="Effect")


@dataclass(frozen=True)
class EffectParam:
    """One parameter of an effect: name (the contract's), SI unit (``"SI"``: the channel's own)
    and kind: ``positive`` (a float > 0, fitted in log coordinates), ``real``, ``channel`` (one
    channel name) or ``channels`` (a list)."""

    name: str
    unit: str
    description: str
    kind: str = "positive"


#: settings of one screening trial of a physical effect (e.g. ``{"gap": 0.01}``)
Trial = dict[str, float]


class Effect:
    """Base class of every effect, built from its parameters by name (:attr:`params`);
    UsageError on an unknown or missing parameter or a value of the wrong kind."""

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
        self.values: dict[str, Any] = {spec.name: _check_value(self.name, spec, values[spec.name])
                                       for spec in self.params}

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
        return {"name": self.name, "params": {
            k: list(v) if isinstance(v, (list, tuple)) else (float(v) if isinstance(v, float) else v)
            for k, v in self.values.items()}}

    @classmethod
    def unavailable_reason(cls, model: SuspensionModel) -> str | None:
        """Why the effect is not defined for ``model`` (``None``: it is), from its structure."""
        return None

    @classmethod
    def limits(cls, model: SuspensionModel) -> dict[str, str]:
        """What the diagnosis cannot identify about this effect with ``model``: ``form ->
        sentence`` (``evidence.limits``)."""
        return {}

    def check_model(self, model: SuspensionModel) -> None:
        """Raise :class:`UsageError` if the effect is not defined for ``model``."""
        why = self.unavailable_reason(model)
        if why is not None:
            raise UsageError(f"effect {self.name} is not available for model {model.name}: {why}")

    def record_problem(self, t: FloatArray) -> str | None:
        """Why the effect cannot act on a record sampled at ``t`` (s); ``None``: it can."""
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

    Besides the force (:meth:`law`) it tells the diagnosis how to find it (:meth:`regressors`,
    :meth:`from_coefficients`, :meth:`screen_trials`, :meth:`base_overrides`; see
    ``docs/architecture.md``).
    """

    kind: ClassVar[str] = "physical"
    #: ``"strut"`` or ``"tyre"``
    site_kind: ClassVar[str] = "strut"
    #: what the evidence figure plots the residual force against: ``"rate"`` or ``"deflection"``
    plot_against: ClassVar[str] = "rate"

    @classmethod
    def model_sites(cls, model: SuspensionModel, p: Mapping[str, float] | None = None) -> list[Site]:
        """Every site of ``model`` of this effect's kind (``p``: parameters, default the model's)."""
        q = model.defaults() if p is None else p
        return model.strut_sites(q) if cls.site_kind == "strut" else model.tyre_sites(q)

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
        """The effect as a ``model.extra_force`` term ``f(t, x, u, params) -> Q`` (unchecked:
        :func:`~suspid.effects.inject` checks the model, :meth:`sites` the parameters)."""

        def f(t: float, x: FloatArray, u: FloatArray, params: Mapping[str, float]) -> FloatArray:
            return self.generalized_force(model, x, u, params)[0]

        f.effect = self  # type: ignore[attr-defined]
        return f

    def base_overrides(self, sites: Sequence[Site]) -> dict[str, float]:
        """Base parameters (SI) the effect's parameters determine at ``sites``, so the refit ties
        them (an asymmetric damper's symmetric part is ``c``); ValueError if not one value."""
        return {}

    @classmethod
    def screen_trials(cls, sites: Sequence[Site], s: Sequence[FloatArray],
                      sd: Sequence[FloatArray]) -> list[Trial]:
        """Settings tried when screening, given each site's coordinate ``s`` (m) and rate ``sd``
        (m/s); empty: the effect cannot show in this record."""
        return [{}]

    @classmethod
    def regressors(cls, site: Site, s: FloatArray, sd: FloatArray, base: Mapping[str, float],
                   trial: Trial, rate_noise: float) -> list[FloatArray]:
        """Force (N) per unit of each coefficient at ``site``: ``phi ~ sum_j beta_j col_j``, from
        the site coordinate ``s`` (m), rate ``sd`` (m/s), the fitted ``base`` (SI), one trial and
        the noise left in ``sd`` (m/s)."""
        raise NotImplementedError(f"effect {cls.name}: no screening regressors")

    @classmethod
    def from_coefficients(cls, coef: FloatArray, base: Mapping[str, float], trial: Trial,
                          sites: Sequence[Site], rate_noise: Sequence[float]
                          ) -> tuple[dict[str, Any], bool, str]:
        """``(params, plausible, note)`` from the coefficients of :meth:`regressors`: the refit's
        start, whether physical, a sentence for the evidence. Default: one parameter, > 0."""
        names = [p.name for p in cls.params if p.kind in ("positive", "real")]
        if len(names) != 1 or len(cls.params) != 1:
            raise NotImplementedError(f"effect {cls.name}: no screening coefficients")
        return {names[0]: float(coef[0])}, float(coef[0]) > 0, ""


class SensorEffect(Effect):
    """An effect in the measurement model (what the sensors report); its diagnosis hooks are
    :meth:`screen_groups`, :meth:`output_sensitivity` and :meth:`params_from_screen`."""

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
        return [c for p in self.params if p.kind in ("channels", "channel")
                for c in (self.values[p.name] if p.kind == "channels" else [self.values[p.name]])]

    @classmethod
    def screen_groups(cls, model: SuspensionModel, measured: Sequence[str]) -> list[list[str]]:
        """Channel groups the effect may affect (default: each measured channel alone)."""
        return [[c] for c in measured]

    @classmethod
    def output_sensitivity(cls, channel: str, t: FloatArray,
                           predicted: Mapping[str, FloatArray]) -> FloatArray | None:
        """Change of ``channel``'s reading per unit of the screened parameter, linearised about
        no effect, from the fitted channels ``predicted`` (``None``: cannot be formed)."""
        raise NotImplementedError(f"effect {cls.name}: no output sensitivity")

    @classmethod
    def params_from_screen(cls, group: Sequence[str], value: float,
                           max_delay: float) -> dict[str, Any] | None:
        """The effect's parameters for ``group`` and screened ``value`` (``None``: not physical)."""
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


def load_plugins() -> None:
    """Add the effects of the entry-point group ``suspid.effects`` to :data:`REGISTRY` (once).
    UsageError, naming the entry point and its package, for a plugin that cannot load, is no
    effect class, lacks a hook or takes a taken name."""
    global _plugins_loaded
    if _plugins_loaded:
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


#: small counts in words
_NUMBER = {2: "two", 3: "three", 4: "four", 5: "five", 6: "six"}


def _short(site_name: str) -> str:
    """``"front strut"`` -> ``"front"``."""
    return site_name.rsplit(" ", 1)[0] if " " in site_name else site_name


def _and(items: Sequence[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    items = list(items)
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]
