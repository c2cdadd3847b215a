"""Experiments built from the designs: truth, initial states and recorded choices."""
from __future__ import annotations

from typing import Mapping

import numpy as np
import pytest

from estimator.doe.arrays import L27_ARRAY, L27_LEVELS
from estimator.doe.design import DESIGNS, design_spec, experiments, setup_record
from suspid.errors import UsageError
from suspid.models import MODELS, DoeDesign, ParamSpec, SuspensionModel, get_model
from suspid.models.base import Matrices
from suspid.models.half4 import DOE_BODY_X0 as HALF4_BODY_X0
from suspid.models.half4 import DOE_CONSTANTS as HALF4_CONSTANTS


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


def test_the_designs_are_the_models_own() -> None:
    """Each model declares its design; the registry of designs is read from the models."""
    assert {k: DESIGNS[k] for k in ("quarter1", "quarter2", "half4", "full7")} == {
        "quarter1": "L16-4", "quarter2": "L27-3", "half4": "L27-3", "full7": "L27-3"}
    for name in MODELS:
        m = get_model(name)
        assert (name in DESIGNS) == (m.doe_design is not None)
    with pytest.raises(UsageError, match="no design for model 'spring1'; expected one of "
                                         "quarter1, quarter2, half4, full7"):
        experiments(_Spring(None))


class _Spring(SuspensionModel):
    """A one-mass model from outside the project, with a design of its own array."""

    def __init__(self, design: DoeDesign | None) -> None:
        super().__init__(name="spring1", coords=("z",), roads=("y",),
                         params=(ParamSpec("m", "kg", 10.0, "mass", "mass"),
                                 ParamSpec("c", "N s/m", 5.0, "damping", "damper"),
                                 ParamSpec("k", "N/m", 100.0, "stiffness", "spring")))
        self._design = design

    @property  # type: ignore[override]
    def doe_design(self) -> DoeDesign | None:  # an instance's design (a class attribute also does)
        return self._design

    def matrices(self, p: Mapping[str, float]) -> Matrices:
        m, c, k = p["m"], p["c"], p["k"]
        return (np.array([[m]]), np.array([[c]]), np.array([[k]]), np.array([[k]]),
                np.array([[c]]))


def test_a_new_model_brings_its_own_design_and_array() -> None:
    own = DoeDesign("L4-2", {"A": "z", "B": "c", "C": "k"}, constants={"m": 12.0},
                    body_x0={"z_dot": 0.1}, choices={"m": "12 kg: weighed"},
                    rows=((1, 1, 1), (1, 2, 2), (2, 1, 2), (2, 2, 1)),
                    levels={"A": ("z0", "m", (0.01, 0.02)), "B": ("c", "N s/m", (4.0, 8.0)),
                            "C": ("k", "N/m", (90.0, 110.0))})
    m = _Spring(own)
    exps = experiments(m)
    assert [e.id for e in exps] == [1, 2, 3, 4]
    assert [(e.truth["c"], e.truth["k"], e.x0[0]) for e in exps] == [
        (4.0, 90.0, 0.01), (8.0, 110.0, 0.01), (4.0, 110.0, 0.02), (8.0, 90.0, 0.02)]
    assert all(e.truth["m"] == 12.0 and e.x0[1] == 0.1 for e in exps)
    rec = setup_record(m)
    assert rec["choices"] == {"m": "12 kg: weighed"} and rec["column_mapping"]["B"] == "c -> c"
    # a seed array with a factor the model does not use (qcar5 has no tyre damper: J unused)
    seed = DoeDesign("L27-3", {"A": "z", "B": "z_dot", "E": "m", "F": "c", "G": "k"})
    spec = design_spec(_Spring(seed))
    assert spec.name == "L27-3" and list(spec.levels) == ["A", "B", "E", "F", "G"]
    np.testing.assert_array_equal(spec.array, L27_ARRAY[:, [0, 1, 4, 5, 6]])
    assert len(experiments(_Spring(seed))) == 27


@pytest.mark.parametrize("design,needle", [
    (DoeDesign("L99-9", {"A": "c"}), "design array 'L99-9' is not one of the seed's"),
    (DoeDesign("L16-4", {"A": "z", "B": "z_dot", "C": "m", "D": "c", "E": "wheelbase"}),
     "maps E -> wheelbase"),
    (DoeDesign("L16-4", {"A": "z", "B": "z_dot", "C": "m", "D": "c"}), "gives no value to k"),
    (DoeDesign("L16-4", {"A": "z", "B": "z_dot", "C": "m", "D": "c", "E": "k"},
               body_x0={"q": 1.0}), "sets q, which are not its parameters or states"),
])
def test_a_wrong_design_is_one_usage_error_naming_the_model(design: DoeDesign, needle: str) -> None:
    with pytest.raises(UsageError, match="model spring1: .*" + needle.replace("(", r"\(")):
        experiments(_Spring(design))
