"""The streaming monitor on every model with a body and wheels: the excitation gate uses the
model's own suspension deflections, and half4 and full7 are monitored end to end."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from estimator.identify import Parameters
from estimator.stream.config import default_config
from estimator.stream.drivers import run_arrays
from estimator.stream.pipeline import make_estimator, monitor_spec
from estimator.stream.wear_streams import damper_wear, write_log
from estimator.stream.window import SlidingWindowIdentifier
from suspid.errors import InputError
from suspid.models import get_model

#: free parameters of the monitor per model (masses, inertias, geometry and tyres known)
FREE = {"half4": ["c1", "c2", "k1", "k2"],
        "full7": ["c1", "c2", "c3", "c4", "k1", "k2", "k3", "k4"]}


def _identifier(name: str, nominal: dict[str, float]) -> SlidingWindowIdentifier:
    m = get_model(name)
    free = FREE[name]
    params = Parameters.for_model(m, fix={k: v for k, v in nominal.items() if k not in free},
                                  init={k: 0.8 * nominal[k] for k in free})
    return SlidingWindowIdentifier(m, params, default_config(m, nominal, 500.0, len(free)),
                                   list(m.coords))


@pytest.mark.parametrize("name", list(FREE))
def test_gate_skips_a_rigid_body_shake_without_suspension_deflection(name: str) -> None:
    """The whole car shaken on a rig (heave and pitch, wheels with the body) does not deflect
    the struts. The old half4 gate took ``x - delta`` (metres minus radians) as the
    deflection and fitted this window; the model's deflections are zero, so it is skipped."""
    m = get_model(name)
    p = m.defaults()
    ident = _identifier(name, p)
    t = np.arange(0, ident.config.window_s, 1 / 500.0)
    rng = np.random.default_rng(1)
    x = 0.02 * np.sin(2 * np.pi * 1.5 * t)
    delta = 0.03 * np.sin(2 * np.pi * 0.9 * t)
    data = {"x": x, "delta": delta, "phi": 0.01 * np.sin(2 * np.pi * 1.1 * t)}
    body = [j for j, c in enumerate(m.coords) if c in data]
    for site, c in zip(m.strut_sites(p), [c for c in m.coords if c not in data]):
        # wheel = body corner point: zero extension
        data[c] = sum(site.g[j] * data[m.coords[j]] for j in body)
    data = {c: v + rng.normal(0, 1e-5, t.size) for c, v in data.items() if c in m.coords}
    assert np.std(data["x"] - data["delta"]) > 0.01   # what the old gate saw: 14+ mm RMS
    ex, reason = ident.excitation(t, data)
    assert "too little excitation" in reason and "suspension deflection" in reason
    assert ex["deflection_rms"] < 1e-4


@pytest.mark.parametrize("name", list(FREE))
def test_gate_measures_the_most_excited_strut(name: str) -> None:
    m = get_model(name)
    s = damper_wear(m, duration=6.0, wear_start=1e6, wear_end=2e6, seed=2, channels=m.coords)
    ident = _identifier(name, s.nominal)
    n = int(ident.config.window_s * 500) + 1
    data = {k: v[:n] for k, v in s.data.items()}
    ex, reason = ident.excitation(s.t[:n], data)
    assert reason == ""
    defl = m.deflections(data, s.nominal)
    assert len(defl) == len(m.strut_sites(s.nominal))
    assert ex["deflection_rms"] == pytest.approx(max(np.std(v) for v in defl.values()), rel=1e-9)


@pytest.mark.parametrize("name", list(FREE))
def test_windows_recover_the_struts(name: str) -> None:
    m = get_model(name)
    s = damper_wear(m, duration=10.0, wear_start=1e6, wear_end=2e6, seed=5, channels=m.coords)
    ident = _identifier(name, s.nominal)
    res: list = []
    cfg = ident.config
    run_arrays(s.t, s.data, cfg.window_s, cfg.step_s, lambda t, d: res.append(ident.process(t, d)))
    assert len(res) >= 2 and not any(r.skipped for r in res)
    for r in res:
        for k in FREE[name]:
            assert r.params[k] == pytest.approx(s.nominal[k], rel=0.02), (k, r.params[k])
            assert abs(r.params[k] - s.nominal[k]) < 5 * r.stderr[k] + 1e-3 * s.nominal[k]


@pytest.mark.slow
def test_monitor_cli_on_a_full7_log(tmp_path: Path) -> None:
    m = get_model("full7")
    s = damper_wear(m, duration=12.0, wear_start=1e6, wear_end=2e6, seed=4, channels=m.coords)
    log = tmp_path / "f7.log"
    n = write_log(s, str(log), "full7")
    fix = [a for k, v in s.nominal.items() if k not in FREE["full7"] for a in ("--fix", f"{k}={v}")]
    r = subprocess.run([sys.executable, "-m", "suspid", "monitor", "--model", "full7", "--input",
                        str(log), *fix, "--jsonl"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    out = [json.loads(line) for line in r.stdout.splitlines() if line.strip()]
    est = [d for d in out if d["type"] == "estimate"]
    assert out[-1]["type"] == "summary" and out[-1]["frames"]["accepted"] == n
    assert est and not [d for d in out if d["type"] == "alert"]
    for d in est:
        assert set(d["stderr"]) == set(FREE["full7"])
        for k in FREE["full7"]:
            assert d["params"][k] == pytest.approx(s.nominal[k], rel=0.03), k


@pytest.mark.parametrize("baseline", ["nm", "ekf"])
def test_one_missing_road_is_named(baseline: str) -> None:
    """A full car whose rear-left road message never came: the error names that road, r3
    (was: "the stream carries no road input r1, r2, r3, r4" while r1, r2 and r4 were in it)."""
    m = get_model("full7")
    spec = monitor_spec(m, fix={"m": 1400.0}, baseline=baseline)
    chans = ["x", "delta", "phi", "x1", "x2", "x3", "x4", "r1", "r2", "r4"]
    with pytest.raises(InputError, match=r"no road input r3 of model full7's r1, r2, r3, r4"):
        make_estimator(spec, chans, 500.0)
