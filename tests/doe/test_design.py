"""Experiments built from the designs: truth, initial states and recorded choices."""
from __future__ import annotations

import numpy as np
import pytest

from estimator.doe.arrays import L27_ARRAY, L27_LEVELS
from estimator.doe.design import HALF4_BODY_X0, HALF4_CONSTANTS, experiments, setup_record
from suspid.models import get_model


@pytest.mark.parametrize("name,count", [("quarter1", 16), ("quarter2", 27), ("half4", 27)])
def test_design_sizes_and_truth_cover_every_parameter(name: str, count: int) -> None:
    m = get_model(name)
    exps = experiments(name)
    assert len(exps) == count
    assert [e.id for e in exps] == list(range(1, count + 1))
    for e in exps:
        assert list(e.truth) == list(m.param_names)
        assert all(v > 0 for v in e.truth.values())
        assert e.x0.shape == (m.n_states,)


def test_half4_follows_seed_section_6_1_and_maps_columns_by_name() -> None:
    m = get_model("half4")
    states = list(m.state_names)
    for e, row in zip(experiments(m), L27_ARRAY):
        for k in ("a1", "a2", "k3", "k4", "m", "I"):
            assert e.truth[k] == HALF4_CONSTANTS[k]
        for s, v in HALF4_BODY_X0.items():
            assert e.x0[states.index(s)] == v
        lv = {f: L27_LEVELS[f][2][row[j] - 1] for j, f in enumerate("ABCDEFGHJK")}
        assert (e.truth["m1"], e.truth["c1"], e.truth["k1"]) == (lv["E"], lv["F"], lv["G"])
        assert (e.truth["m2"], e.truth["c2"], e.truth["k2"]) == (lv["H"], lv["J"], lv["K"])
        assert e.x0[states.index("x1")] == lv["A"] and e.x0[states.index("x1_dot")] == lv["B"]
        assert e.x0[states.index("x2")] == lv["C"] and e.x0[states.index("x2_dot")] == lv["D"]


def test_half4_dynamic_index_is_not_one() -> None:
    c = HALF4_CONSTANTS
    di = c["I"] / (c["m"] * c["a1"] * c["a2"])
    assert 0.7 < di < 0.9


def test_setup_record_names_every_choice_the_seed_leaves_out() -> None:
    rec = setup_record("half4")
    for key in ("column_mapping", "m", "I", "horizon_s", "sample_rate_hz"):
        assert key in rec["choices"]
    assert rec["samples"] == int(round(rec["horizon_s"] * rec["sample_rate_hz"])) + 1
    assert rec["cost_channels"]["sse"] == ["x", "delta", "x1", "x2"]


def test_every_design_row_is_stable_and_underdamped_or_overdamped_not_defective() -> None:
    for name in ("quarter1", "quarter2", "half4"):
        m = get_model(name)
        for e in experiments(m):
            A, _ = m.state_space(e.truth)
            lam = np.linalg.eigvals(A)
            assert np.all(lam.real < 0), (name, e.id)
