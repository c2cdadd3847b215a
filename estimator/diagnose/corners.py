"""Where an effect acts: one strut of a half car, and what a model cannot tell apart.

The effect library (:mod:`suspid.models.effects`) applies a strut effect of ``half4`` to
*both* struts with one parameter set (the same hardware front and rear) and does not offer
``asymmetric_damping`` there. A worn or sticking damper is usually one corner, though, so
``diagnose`` also tests every strut effect in the front or the rear strut alone
(:class:`SiteRestricted`, diagnose-internal: the contract's effect parameters are unchanged
and the strut is reported in ``evidence.effect_sites``). What no candidate form can express
for a model is listed by :func:`model_limits` and said in the verdict instead of guessed.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

from suspid.errors import UsageError
from suspid.models.base import SuspensionModel
from suspid.models.effects import PhysicalEffect, Site, strut_sites, tyre_sites
from suspid.models.effects import Law


class SiteRestricted(PhysicalEffect):
    """A library physical effect acting at some of its sites only (e.g. the front strut).

    Parameters
    ----------
    inner : PhysicalEffect
        The library effect (its parameters, law and JSON form are used unchanged).
    site_names : sequence of str
        Names of the sites it acts at (``"front strut"``, ``"rear strut"``).

    Notes
    -----
    The restriction bypasses the library's model list on purpose: ``asymmetric_damping`` in
    *one* strut of ``half4`` is well defined (its symmetric part is that strut's ``c1`` or
    ``c2``); only the shared two-strut form is not.
    """

    def __init__(self, inner: PhysicalEffect, site_names: Sequence[str]) -> None:
        self.inner = inner
        self.site_names = list(site_names)
        self.values = inner.values
        self.name = inner.name  # type: ignore[misc]
        self.params = inner.params  # type: ignore[misc]
        self.site_kind = inner.site_kind  # type: ignore[misc]
        self.description = f"{inner.description} ({', '.join(self.site_names)} only)"  # type: ignore[misc]

    def sites(self, model: SuspensionModel, p: Mapping[str, float]) -> list[Site]:
        """The named sites of ``model`` (UsageError if it has none of them)."""
        every = strut_sites(model, p) if self.site_kind == "strut" else tyre_sites(model, p)
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


def effect_sites(effect: PhysicalEffect, model: SuspensionModel, p: Mapping[str, float]) -> list[str]:
    """Names of the sites ``effect`` acts at in ``model`` (``["front strut", "rear strut"]``)."""
    return [s.name for s in effect.sites(model, p)]


def model_limits(model: SuspensionModel) -> dict[str, str]:
    """What ``diagnose`` cannot identify with ``model``, by effect (empty if nothing).

    Returns
    -------
    dict
        ``effect or form -> reason`` (plain sentences, printed in ``evidence.limits``).
    """
    if model.name == "half4":
        return {
            "asymmetric_damping (both struts)":
                "one (c_rebound, c_compression) pair cannot describe two dampers whose "
                "symmetric parts c1 and c2 differ, and the contract has no per-strut pair; "
                "asymmetric damping is tested in the front or the rear strut alone",
            "strut effect of different size front and rear":
                "the library's half4 strut effects share one parameter set (same hardware "
                "front and rear); an effect is tested in both struts with one value or in "
                "one strut alone, and a front/rear disagreement of the screening regression "
                "is reported in evidence.candidates.NAME.screen.per_site",
        }
    if model.name == "quarter1":
        return {
            "tire_liftoff (wheel hop)":
                "quarter1 has no wheel: its one spring/damper is suspension and tyre in "
                "series, so tire_liftoff can only mean the whole corner leaving the road "
                "(the element cannot pull the body down); a wheel hopping under a body "
                "still held by its spring is not representable (use quarter2)",
        }
    return {}


__all__ = ["SiteRestricted", "effect_sites", "model_limits"]
