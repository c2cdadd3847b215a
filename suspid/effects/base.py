"""The effect library's base: effect parameters, the physical and sensor effect classes and
the registry (built-ins and entry-point plugins); see :mod:`suspid.effects`.
"""

import math
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Any, ClassVar, Mapping, Sequence, TypeVar

import numpy as np

# scipy.interpolate (which loads scipy.optimize, ~0.2 s) is reached through scipy's lazy
# submodule attribute, so a monitor that never resamples a channel does not pay for it
from suspid.errors import UsageError
from suspid.models.base import FloatArray, ForceFn, Site, SuspensionModel
from suspid.nlsim import Law

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


#: small counts in words
_NUMBER = {2: "two", 3: "three", 4: "four", 5: "five", 6: "six"}


def _short(site_name: str) -> str:
    """``"front strut"`` -> ``"front"``."""
    return site_name.rsplit(" ", 1)[0] if " " in site_name else site_name


def _and(items: Sequence[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    items = list(items)
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]
