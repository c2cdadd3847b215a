"""The model registry: built-ins, entry points, one-line errors, models read from CSV columns,
and every model's own facts (rest state, roads, struts, tyres, CAN identities)."""
from __future__ import annotations

import sys
import textwrap
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest

from suspid.errors import UsageError
from suspid.excitation import make_scenario
from suspid.models import BUILTIN, ENTRY_POINT_GROUP, GRAVITY, MODELS, get_model, infer_model
from suspid.simulate import simulate


def test_builtins_are_registered() -> None:
    assert list(BUILTIN) == ["quarter1", "quarter2", "half4", "full7"]
    assert set(BUILTIN) <= set(MODELS)


def test_unknown_model_is_one_line_usage_error_naming_the_known() -> None:
    with pytest.raises(UsageError) as exc:
        get_model("quarter9")
    msg = str(exc.value)
    assert "\n" not in msg and "'quarter9'" in msg
    assert all(n in msg for n in BUILTIN)


@pytest.fixture
def plugin(tmp_path: Path) -> Iterator[str]:
    """An installed distribution (a dist-info on sys.path) registering model ``mycar``."""
    pkg = tmp_path / "suspid_test_mycar"
    pkg.mkdir()
    (pkg / "__init__.py").write_text(textwrap.dedent('''
        import numpy as np
        from suspid.models.base import ParamSpec, Site, SuspensionModel

        class MyCar(SuspensionModel):
            """A stiff single mass on the road (quarter1 with other names)."""

            def __init__(self):
                super().__init__(name="mycar", coords=("z",), roads=("u",),
                                 params=(ParamSpec("M", "kg", 100.0, "mass", "mass"),
                                         ParamSpec("C", "N s/m", 500.0, "damping", "damper"),
                                         ParamSpec("K", "N/m", 1e4, "stiffness", "spring")))

            def matrices(self, p):
                return (np.array([[p["M"]]]), np.array([[p["C"]]]), np.array([[p["K"]]]),
                        np.array([[p["K"]]]), np.array([[p["C"]]]))

            def strut_sites(self, p):
                g = np.array([1.0])
                return [Site("strut", "strut", g, np.array([-1.0]), -g, "C", "K")]

        def broken():
            return 42
    '''))
    dist = tmp_path / "suspid_test_mycar-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: suspid-test-mycar\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text(
        f"[{ENTRY_POINT_GROUP}]\nmycar = suspid_test_mycar:MyCar\nbroken = suspid_test_mycar:broken\n"
        "half4 = suspid_test_mycar:MyCar\n")
    sys.path.insert(0, str(tmp_path))
    MODELS.reload()
    try:
        yield "mycar"
    finally:
        sys.path.remove(str(tmp_path))
        sys.modules.pop("suspid_test_mycar", None)
        MODELS.reload()


def test_entry_point_model_is_found_and_simulates(plugin: str) -> None:
    assert plugin in MODELS
    m = get_model(plugin)
    assert m.name == "mycar" and m.param_names == ("M", "C", "K")
    t, road, x0 = make_scenario(m, "bump", duration=1.0, fs=200.0)
    out = simulate(m, m.defaults(), t, road, x0)
    assert np.max(np.abs(out["z"])) > 0.01
    assert list(m.deflections(out)) == ["strut"]
    # a built-in name is not replaced; a factory returning no model is refused in one line
    assert type(get_model("half4")).__name__ == "Half4"
    with pytest.raises(UsageError, match="broken.*expected a SuspensionModel"):
        get_model("broken")
    assert infer_model(["t", "z", "u"]) == "mycar"


@pytest.mark.parametrize("columns,model", [
    (["x"], "quarter1"), (["x", "y"], "quarter1"), (["x_ddot"], "quarter1"),
    (["x1", "x2", "r"], "quarter2"), (["x1_dot"], "quarter2"),
    (["x", "delta"], "half4"), (["x", "x1", "x2"], "half4"), (["r1"], "half4"),
    (["x1", "r2"], "half4"), (["phi"], "full7"), (["x", "x3"], "full7"),
    (["x1", "x2", "r4_dot"], "full7"), (["x", "r"], "quarter1")])
def test_infer_model_from_csv_columns(columns: list[str], model: str) -> None:
    assert infer_model(["t", *columns]) == model


def test_infer_model_without_model_columns_is_a_usage_error() -> None:
    with pytest.raises(UsageError, match="cannot tell the model"):
        infer_model(["t", "foo"])


@pytest.mark.parametrize("name", list(BUILTIN))
def test_every_model_owns_consistent_facts(name: str) -> None:
    m = get_model(name)
    p = m.defaults()
    assert m.initial_state().shape == (m.n_states,) and np.any(m.initial_state())
    assert len(m.road_tracks()) == len(m.roads) == len(m.road_lags(p))
    assert set(m.known) <= set(m.param_names)
    assert m.sensor_set > 0 and m.alert_id >= 0
    struts, tyres = m.strut_sites(p), m.tyre_sites(p)
    assert struts and tyres
    for s in struts + tyres:
        assert s.g.shape == (len(m.coords),) and s.gr.shape == (len(m.roads),)
        for n in (s.c_name, s.k_name):
            assert n is None or n in m.param_names
    # the tyres carry the whole weight
    masses = sum(v for k, v in p.items() if m.spec(k).kind == "mass")
    assert sum(s.load for s in tyres) == pytest.approx(masses * GRAVITY)
    # the struts' and tyres' springs and dampers are exactly the model's matrices
    _, C, K, _, _ = m.matrices(p)
    sites = struts if name == "quarter1" else struts + tyres  # quarter1's strut is its tyre
    Cs = sum(p[s.c_name] * np.outer(s.g, s.g) for s in sites if s.c_name)
    Ks = sum(p[s.k_name] * np.outer(s.g, s.g) for s in sites if s.k_name)
    np.testing.assert_allclose(Cs, C, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(Ks, K, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("name", list(BUILTIN))
def test_every_road_follows_the_first_road_of_its_track(name: str) -> None:
    m = get_model(name)
    p = m.defaults()
    v = 36.0
    t, road, _ = make_scenario(m, "iso8608", duration=3.0, fs=1000.0, v_kmh=v)
    tracks, lags = m.road_tracks(), m.road_lags(p)
    for i, rn in enumerate(m.roads):
        j = next(k for k in range(len(m.roads)) if tracks[k] == tracks[i])  # track's first road
        k = int(round((lags[i] - lags[j]) / (v / 3.6) * 1000.0))
        ref = road[m.roads[j]]
        np.testing.assert_allclose(road[rn][k:], ref[:ref.size - k], atol=2e-5 * np.ptp(ref))
