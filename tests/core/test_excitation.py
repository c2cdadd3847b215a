"""Road shapes as documented: ISO 8608 PSD levels, curb and bump shapes, measured roads."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import welch

from suspid.excitation import (ISO8608_CLASSES, bump_profile, curb_profile, iso8608_road,
                               measured_road)
from suspid.errors import InputError
from suspid.io.csvio import read_measurement
from suspid.models import get_model


@pytest.mark.parametrize("cls", ["A", "C", "E"])
def test_iso8608_psd_level(cls: str) -> None:
    """Welch PSD of a 4 km road: Gd(n) = Gd(n0) (n / 0.1)^-2 with the class's Gd(n0)."""
    ds = 0.02
    s, z = iso8608_road(4000.0, cls, seed=3, ds=ds)
    n, G = welch(z, fs=1.0 / ds, nperseg=8192)          # one-sided, m^2 / (cycles/m)
    band = (n >= 0.05) & (n <= 2.0)
    ratio = G[band] * (n[band] / 0.1) ** 2 / ISO8608_CLASSES[cls]
    assert np.median(ratio) == pytest.approx(1.0, abs=0.15)
    assert ISO8608_CLASSES[cls] == pytest.approx(16e-6 * 4 ** "ABCDEFGH".index(cls))


def test_curb_rise_is_a_half_cosine_with_finite_rate() -> None:
    h, t0, rise = 0.08, 0.5, 0.02
    t = np.linspace(0, 1, 100_001)
    r, rd = curb_profile(t, h, t0, rise)
    assert np.all(r[t <= t0] == 0) and np.allclose(r[t >= t0 + rise], h)
    assert np.all(np.diff(r) >= -1e-15)                                  # monotonic
    assert rd.max() == pytest.approx(h * math.pi / (2 * rise), rel=1e-6)  # finite peak rate
    mid = np.argmin(np.abs(t - (t0 + rise / 2)))
    assert r[mid] == pytest.approx(h / 2, rel=1e-3)
    np.testing.assert_allclose(rd[1:-1], np.gradient(r, t)[1:-1], atol=h / rise * 2e-3)


def test_bump_is_a_raised_cosine_of_its_length() -> None:
    h, l, v_kmh, t0 = 0.1, 3.0, 20.0, 0.5
    v = v_kmh / 3.6
    t = np.linspace(0, 2, 200_001)
    r, rd = bump_profile(t, h, l, v_kmh, t0)
    assert np.all(r[(t < t0) | (t > t0 + l / v)] == 0)
    assert r.max() == pytest.approx(h, rel=1e-6)
    assert t[np.argmax(r)] == pytest.approx(t0 + l / (2 * v), abs=1e-4)
    assert np.trapezoid(r, t) * v == pytest.approx(h * l / 2, rel=1e-4)   # area of the profile
    np.testing.assert_allclose(rd[1:-1], np.gradient(r, t)[1:-1], atol=h * v / l * 1e-3)


def _suspid(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "suspid", *args], capture_output=True, text=True,
                          timeout=120)


def test_simulate_over_a_measured_road_equals_the_scenario(tmp_path: Path) -> None:
    ref = tmp_path / "bump.csv"
    assert _suspid("simulate", "--model", "quarter2", "--scenario", "bump", "--duration", "3",
                   "--fs", "500", "--out", str(ref)).returncode == 0
    m = read_measurement(ref, get_model("quarter2"))
    road = tmp_path / "road.csv"          # the road only, no r_dot: differentiated numerically
    road.write_text("t,r\n" + "".join(f"{a:.17g},{b:.17g}\n" for a, b in zip(m.t, m.road["r"])))
    out = tmp_path / "over.csv"
    r = _suspid("simulate", "--model", "quarter2", "--road", str(road), "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["scenario"].startswith("measured road")
    got = read_measurement(out, get_model("quarter2"))
    np.testing.assert_array_equal(got.t, m.t)
    for c in ("x1", "x2"):
        err = np.abs(got.measured[c] - m.measured[c]).max() / np.abs(m.measured[c]).max()
        assert err < 1e-6, (c, err)


def test_half4_measured_front_road_delays_the_rear() -> None:
    model = get_model("half4")
    t = np.arange(0, 2, 0.001)
    r1 = np.sin(2 * np.pi * 1.3 * t)
    road = measured_road(model, t, {"r1": r1}, {"a1": 1.2, "a2": 1.4}, v_kmh=36.0)
    delay = 2.6 / 10.0
    k = int(round(delay / 0.001))
    np.testing.assert_allclose(road["r2"][k:], r1[:-k], atol=1e-12)
    assert np.all(road["r2"][:k] == r1[0])
    with pytest.raises(InputError, match="no road column 'r1'"):
        measured_road(model, t, {"r": r1}, source="road.csv")
