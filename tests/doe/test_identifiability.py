"""Scale ambiguity and the minimal prior knowledge (one known mass)."""
from __future__ import annotations

import pytest

from tools.doe_prior import prior_study, scale_ambiguity


@pytest.mark.parametrize("model", ["quarter1", "quarter2", "half4"])
def test_scaling_all_masses_dampers_springs_leaves_the_response(model: str) -> None:
    r = scale_ambiguity(model, 14 if model != "quarter1" else 7, factor=0.6)
    assert r["max_rel_diff"] < 1e-10


def test_unrestricted_quarter2_lands_on_a_scaled_copy_like_the_seed() -> None:
    r = prior_study("quarter2", 14, [])
    assert r["identifiable"] is False and r["success"] is False
    assert any("common factor" in w for w in r["warnings"])
    assert abs(r["common_factor"] - 1) > 0.1
    assert r["spread_about_common_factor"] < 1e-3  # every ratio is the same factor


@pytest.mark.parametrize("model,known", [("quarter2", ["m2"]), ("half4", ["m"])])
def test_one_known_mass_suffices(model: str, known: list[str]) -> None:
    r = prior_study(model, 14, known)
    assert r["identifiable"] is True
    assert r["success"], r["rel_error"]
    assert r["min_singular_value"] > 1e-4
