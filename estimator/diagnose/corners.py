"""Where an effect acts: one strut of a model with several, and what a model cannot tell apart.

The library applies a strut effect to every strut with one parameter set; a worn damper is
usually one corner, so ``diagnose`` also tries each strut alone (:class:`SiteRestricted`).
What no candidate form can express is listed by :func:`model_limits`.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

from suspid.errors import UsageError
from suspid.models.base import SuspensionModel
from suspid.effects import Law, PhysicalEffect, Site, effect_classes


class SiteRestricted(PhysicalEffect):
    """A library physical effect acting at some of its sites only (``site_names``, e.g. the front strut).

    It bypasses the library's availability rule on purpose: ``asymmetric_damping`` in one strut of
    ``half4`` is well defined.
    """

    def __init__(self, inner: PhysicalEffect, site_names: Sequence[str]) -> None:
        self.inner = inner
        self.site_names = list(site_names)
        self.values = inner.values
        self.name = inner.name  # type: ignore[misc]
        self.params = inner.params  # type: ignore[misc]
        self.site_kind = inner.site_kind  # type: ignore[misc]
        self.plot_against = inner.plot_against  # type: ignore[misc]
        self.description = f"{inner.description} ({', '.join(self.site_names)} only)"  # type: ignore[misc]

    def sites(self, model: SuspensionModel, p: Mapping[str, float]) -> list[Site]:
        """The named sites of ``model`` (UsageError if it has none of them)."""
        every = self.inner.model_sites(model, p)
        chosen = [s for s in every if s.name in self.site_names]
        if not chosen:
            raise UsageError(f"effect {self.name}: model {model.name} has no site "
                             f"{', '.join(self.site_names)}; expected any of "
                             f"{', '.join(s.name for s in every)}")
        return chosen

    def check_model(self, model: SuspensionModel) -> None:
        """Defined wherever the named sites exist (checked by :meth:`sites`)."""

    def law(self, site: Site, base: Mapping[str, float]) -> Law:
        return self.inner.law(site, base)

    def base_overrides(self, sites: Sequence[Site]) -> dict[str, float]:
        return self.inner.base_overrides(sites)

    def with_values(self, **values: Any) -> "SiteRestricted":
        inner = self.inner.with_values(**values)
        if not isinstance(inner, PhysicalEffect):
            raise TypeError("SiteRestricted wraps physical effects only")
        return SiteRestricted(inner, self.site_names)

    def __repr__(self) -> str:
        return f"SiteRestricted({self.inner!r}, {self.site_names!r})"

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, SiteRestricted) and self.inner == other.inner
                and self.site_names == other.site_names)


def _struts(model: SuspensionModel) -> list[Site]:
    try:
        return model.strut_sites(model.defaults())
    except UsageError:
        return []


def strut_limit_key(model: SuspensionModel) -> str:
    """Key of the limit "a strut effect of different size in each strut" for ``model``."""
    names = [s.name.rsplit(" ", 1)[0] for s in _struts(model)]
    return ("strut effect of different size " + (" and ".join(names) if len(names) == 2
                                                 else "per strut"))


def model_limits(model: SuspensionModel) -> dict[str, str]:
    """What ``diagnose`` cannot identify with ``model``: ``effect or form -> reason``."""
    out: dict[str, str] = {}
    for cls in effect_classes().values():
        out.update(cls.limits(model))
    struts = _struts(model)
    if len(struts) > 1:
        n = len(struts)
        names = [s.name.rsplit(" ", 1)[0] for s in struts]
        hardware = " and ".join(names) if n == 2 else "at every corner"
        pair = "/".join(names) if n == 2 else "strut-to-strut"
        out[strut_limit_key(model)] = (
            f"the library's {model.name} strut effects share one parameter set (same hardware "
            f"{hardware}); an effect is tested in {'both' if n == 2 else 'all'} struts with one "
            f"value or in one strut alone, and a {pair} disagreement of the screening regression "
            "is reported in evidence.candidates.NAME.screen.per_site")
    return out
