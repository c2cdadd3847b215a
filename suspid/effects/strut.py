"""Physical effects: strut and tyre forces the linear models lack (dry friction, asymmetric
and quadratic damping, a progressive spring, a bump stop, tyre lift-off).
"""

import math
from typing import Any, Mapping, Sequence

import numpy as np

from suspid.effects.base import _NUMBER, EffectParam, PhysicalEffect, Trial, _and, _short, register
from suspid.errors import UsageError
from suspid.models.base import FloatArray, Site, SuspensionModel
from suspid.nlsim import Law

#: velocity scale (m/s) of the smoothed sign in ``coulomb_friction``: ``F tanh(d'/V_EPS)``
V_EPS = 0.01

@register
class CoulombFriction(PhysicalEffect):
    """Dry friction in the strut: ``F sgn(d')``, sign smoothed as ``tanh(d'/V_EPS)``.

    A noisy measured rate flips the sign while the strut sticks, shrinking ``F``: screening
    uses the softer ``tanh(d'/w)``, ``w = hypot(V_EPS, m 1.2 sigma_rate)``, ``m`` = 1, 2, 4, 8.
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

    It replaces the linear damper ``c1 d'`` (reported as the symmetric part, the mean of the
    two); available only where one damper coefficient describes every strut.
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
        # |d'| = max(d', 0) - min(d', 0): split symmetrically about the fitted c
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
    """Bump stop: ``k_stop (-d - gap)`` pushes back once the compression exceeds ``gap``;
    screened at gaps from 15 % to 90 % of the record's largest compression."""

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
            struts = model.strut_sites(model.defaults())
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
