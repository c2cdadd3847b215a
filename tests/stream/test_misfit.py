"""A wrong ``--fix`` is said, once: the windows' fits leave far more than white noise.

With the body mass held at twice the truth (and the tyre at the truth) every window's fit
left 13-20x the noise floor on the wheel and ~2x on the body while the monitor printed
confident estimates (c1 ~3600 with a stderr of 30) without a word. Now every estimate
carries its ``noise_floor_ratio`` and ``misfit``, and a persistent misfit gives one
``warning`` line (and a line on stderr) naming the ratio, the channels and the causes.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from estimator.identify import OutputErrorProblem
from estimator.identify.misfit import noise_floor_ratio, noise_floor_ratios
from estimator.stream.misfit import MISFIT_RATIO, MISFIT_WINDOWS, MisfitWatch, misfit_shares
from estimator.stream.wear_streams import damper_wear
from suspid.io.csvio import Measurement, write_measurement
from suspid.models import get_model

TYRE = ["--fix", "m2=40", "--fix", "c2=300", "--fix", "k2=200000"]


@pytest.fixture(scope="module")
def csv(tmp_path_factory):
    """30 s of quarter2 on a random road (no wear), the wear streams' noise."""
    s = damper_wear(get_model("quarter2"), duration=30.0, wear_start=100.0, seed=13)
    path = tmp_path_factory.mktemp("misfit") / "q2.csv"
    write_measurement(path, s.t, s.data)
    return path


def _monitor(path, *fix: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "suspid", "monitor", "--model", "quarter2",
                           "--input", str(path), *fix, "--jsonl", "--no-inspection"],
                          capture_output=True, text=True, timeout=300)


def test_a_wrong_fix_is_warned_once_and_its_estimates_marked(csv) -> None:
    r = _monitor(csv, "--fix", "m1=600", *TYRE)
    assert r.returncode == 0, r.stderr
    out = [json.loads(l) for l in r.stdout.splitlines() if l.strip()]
    warn = [d for d in out if d["type"] == "warning"]
    assert len(warn) == 1
    w = warn[0]
    assert w["kind"] == "misfit" and w["ratio"] > 3 * MISFIT_RATIO
    assert "x2" in w["channels"] and w["windows"] == MISFIT_WINDOWS
    assert w["fixed"]["m1"] == 600.0
    for word in ("--fix", "m1=600", "suspid diagnose", "x2"):
        assert word in w["message"]
    est = [d for d in out if d["type"] == "estimate"]
    assert len(est) >= MISFIT_WINDOWS + 2
    assert all(d["misfit"] for d in est)
    assert all(max(d["noise_floor_ratio"].values()) > MISFIT_RATIO for d in est)
    # the warning comes right after the estimate that made the misfit persistent
    i = out.index(w)
    assert out[i - 1]["type"] == "estimate" and out[i - 1]["t"] == w["t"]
    assert out[-1]["misfit_windows"] == len(est)
    err = [l for l in r.stderr.splitlines() if "fits persistently" in l]
    assert len(err) == 1 and err[0].startswith("warning: ") and "m1=600" in err[0]


def test_the_correct_fix_fits_at_the_noise_floor_and_does_not_warn(csv) -> None:
    r = _monitor(csv, "--fix", "m1=300", *TYRE)
    assert r.returncode == 0, r.stderr
    out = [json.loads(l) for l in r.stdout.splitlines() if l.strip()]
    assert not [d for d in out if d["type"] == "warning"]
    assert "fits persistently" not in r.stderr
    est = [d for d in out if d["type"] == "estimate"]
    assert len(est) >= 15
    for d in est:
        assert d["misfit"] is False
        assert set(d["noise_floor_ratio"]) == {"x1", "x2"}
        assert 0.8 < min(d["noise_floor_ratio"].values())
        assert max(d["noise_floor_ratio"].values()) < 3.0   # well below MISFIT_RATIO
    assert out[-1]["misfit_windows"] == 0


def test_the_watch_wants_consecutive_windows_and_warns_once() -> None:
    w = MisfitWatch({"m1": 600.0})
    bad = {"x1": 1.2 * MISFIT_RATIO, "x2": 3.0 * MISFIT_RATIO}
    good = {"x1": 1.0, "x2": 0.9 * MISFIT_RATIO}
    seq = [bad] * (MISFIT_WINDOWS - 1) + [good] + [bad] * (MISFIT_WINDOWS + 2)
    flags, notes = [], []
    for i, r in enumerate(seq):
        f, n = w.update(float(i), r)
        flags.append(f)
        if n is not None:
            notes.append((i, n))
    assert flags == [r is bad for r in seq]
    assert len(notes) == 1
    i, n = notes[0]
    assert i == 2 * MISFIT_WINDOWS - 1          # the MISFIT_WINDOWS-th bad one after the good
    assert n.to_json()["type"] == "warning" and n.fields["since"] == float(MISFIT_WINDOWS)
    assert list(n.fields["channels"]) == ["x2", "x1"]          # worst first
    assert w.count == seq.count(bad)
    # a channel that cannot be evaluated (inf) counts as above, a NaN never hides one
    assert w.update(99.0, {"x1": math.inf})[0]


def test_per_channel_ratios_add_up_to_the_identify_measure(quarter2) -> None:
    """:func:`noise_floor_ratios` is :func:`noise_floor_ratio` channel by channel: the same
    measure that ``suspid identify`` uses to recognise a fit at the noise floor."""
    rng = np.random.default_rng(3)
    s = damper_wear(quarter2, duration=4.0, wear_start=100.0, seed=4,
                    noise={c: 0.0 for c in ("x1", "x2", "x1_ddot", "r", "r_dot")},
                    quantize=False)
    meas = {c: s.data[c] + rng.normal(0, 0.05 * np.std(s.data[c]), s.t.size) for c in ("x1", "x2")}
    prob = OutputErrorProblem(quarter2, Measurement(s.t, {"r": s.data["r"], "r_dot": s.data["r_dot"]},
                                                    meas, source="test"))
    truth = dict(quarter2.defaults())
    per = noise_floor_ratios(prob, truth)
    assert set(per) == {"x1", "x2"}
    for v in per.values():
        assert v == pytest.approx(1.0, abs=0.15)
    off = dict(truth, k2=0.5 * truth["k2"])
    per_off = noise_floor_ratios(prob, off)
    assert max(per_off.values()) > 5.0
    assert min(per_off.values()) < noise_floor_ratio(prob, off) < max(per_off.values())


@pytest.mark.slow
def test_a_noise_free_record_is_no_misfit_as_identify_says(tmp_path) -> None:
    """A noise-free ISO 8608 record: ``identify`` fits it to 1e-19 and calls it a success;
    each window's ratio compares rounding and interpolation errors (12-22, above
    ``MISFIT_RATIO``) on a residual a millionth of the signal. The monitor now judges as
    identify does (was: every window misfit and the warning)."""
    path = tmp_path / "clean.csv"
    assert subprocess.run([sys.executable, "-m", "suspid", "simulate", "--model", "quarter2",
                           "--scenario", "iso8608", "--duration", "12", "--fs", "200",
                           "--out", str(path)], capture_output=True, timeout=120).returncode == 0
    ident = subprocess.run([sys.executable, "-m", "suspid", "identify", "--model", "quarter2",
                            "--input", str(path), "--fix", "m1=300", "--json"],
                           capture_output=True, text=True, timeout=300)
    res = json.loads(ident.stdout)
    assert res["success"] and not any(w.startswith("misfit") for w in res["warnings"])
    r = _monitor(path, "--fix", "m1=300")
    out = [json.loads(l) for l in r.stdout.splitlines() if l.strip()]
    est = [d for d in out if d["type"] == "estimate"]
    assert len(est) >= 5
    assert any(max(d["noise_floor_ratio"].values()) > MISFIT_RATIO for d in est)
    assert not any(d["misfit"] for d in est)
    assert not [d for d in out if d["type"] == "warning" and d["kind"] == "misfit"]
    assert out[-1]["misfit_windows"] == 0
    # a wrong tyre held on the same record is still a misfit in every window
    wrong = [json.loads(l) for l in _monitor(path, "--fix", "m1=300", "--fix",
                                             "k2=400000").stdout.splitlines() if l.strip()]
    assert wrong[-1]["misfit_windows"] == wrong[-1]["windows"] > 0


def test_shares_follow_identify_measure() -> None:
    """The share is the residual's excess over its noise floor over the window's signal."""
    t = np.arange(400) * 0.01
    y = np.sin(t)
    data = {"x1": y, "x2": 2 * y}
    var = float(np.var(y) + np.var(2 * y))
    sh = misfit_shares({"x1": 4.0, "x2": math.inf}, {"x1": 0.1, "x2": 0.2}, data)
    assert sh["x1"] == pytest.approx(0.01 * 0.75 / var)
    assert sh["x2"] == pytest.approx(0.04 / var)
    w = MisfitWatch()
    assert not w.update(0.0, {"x1": 800.0}, {"x1": 1e-8})[0]
    assert w.update(1.0, {"x1": 800.0}, {"x1": 1e-3})[0]
