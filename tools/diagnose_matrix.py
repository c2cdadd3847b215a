"""Effect matrix of ``suspid diagnose``: the tables of ``docs/closing-the-loop.md``.

For every model and every effect of the library that applies to it, a record with the
effect injected (1.6 s at 200 Hz, 0.5 % white noise on every channel; the same recipe and
cases as ``tests/diagnose/``) is diagnosed with the masses (and the half car's geometry)
known and every stiffness and damping started at 0.7 x the truth. Plus, per model, a record
without effect, one with a 9 Hz body shake no library effect explains and, for the half
car, effects in one strut only and asymmetric dampers in both struts (not identifiable);
for the full car (masses, inertias and geometry known: the model's ``known`` set) a
sample of effects on four struts / tyres, one corner, and none.

Usage::

    python tools/diagnose_matrix.py                       # quarter1 and half4, Markdown
    python tools/diagnose_matrix.py --model quarter2      # the seed's quarter car
    python tools/diagnose_matrix.py --model full7         # the 7-DOF full car
    python tools/diagnose_matrix.py --json                # one JSON object per case

Columns: injected effect; road; what diagnose selected (``none`` with the verdict's
gist when it selected nothing); the effect's parameters as estimated with their error
against the injected ones; the largest error of the free base parameters (symmetric part
for an asymmetric damper) in the linear baseline and after augmentation; the RMS residual
of the body channel and the mean RMS ratio over all channels; the wall time (loaded 2-core
machine).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository: tools.*

from tools.synthetic_record import synthetic_record  # noqa: E402
from estimator.diagnose import diagnose
from estimator.diagnose.corners import SiteRestricted
from estimator.identify import Parameters
from suspid.models import get_model
from suspid.effects import Effect, PhysicalEffect, parse_effect

#: the seed's Table 1 quarter car (SI)
TABLE1 = dict(m1=275.0, k1=150000.0, c1=1120.0, m2=27.0, k2=310000.0, c2=3100.0)
TRUTH: dict[str, dict[str, float]] = {
    "quarter1": get_model("quarter1").defaults(),
    "quarter2": TABLE1,
    "half4": dict(get_model("half4").defaults(), c1=1800.0, c2=2400.0, k1=28000.0, k2=35000.0,
                  k3=220000.0, k4=190000.0),
    # every corner different, so a mix-up of corners shows
    "full7": dict(get_model("full7").defaults(), c1=1800.0, c2=2000.0, c3=1500.0, c4=1700.0,
                  k1=27000.0, k2=29000.0, kt1=210000.0, kt4=190000.0),
}
FIXED = {"quarter1": ("m",), "quarter2": ("m1", "m2"), "half4": ("m", "I", "m1", "m2", "a1", "a2"),
         "full7": tuple(get_model("full7").known)}
FREE = {"quarter1": ("c", "k"), "quarter2": ("c1", "k1", "c2", "k2"),
        "half4": ("c1", "c2", "k1", "k2", "k3", "k4"),
        "full7": tuple(k for k in get_model("full7").param_names if k not in FIXED["full7"])}
BODY = {"quarter1": "x", "quarter2": "x1", "half4": "x", "full7": "x"}


def _in(strut: str, spec: str) -> Effect:
    eff = parse_effect(spec)
    if not isinstance(eff, PhysicalEffect):
        raise TypeError(spec)
    return SiteRestricted(eff, [strut])


def _shake(model: str) -> Any:
    def f(t: float, x: np.ndarray, u: np.ndarray, p: Any) -> np.ndarray:
        out = np.zeros(len(get_model(model).coords))
        out[0] = (150.0 if model == "quarter1" else 300.0) * math.sin(2 * math.pi * 9.0 * t)
        if len(out) > 1:   # pitch of a half or full car
            out[1] = 150.0 * math.sin(2 * math.pi * 7.0 * t)
        return out
    return f


#: model -> (label, effects, scenario, scenario options, extra force or None)
CASES: dict[str, list[tuple[str, list[Any], str, dict[str, Any], Any]]] = {
    "quarter1": [(s, [s], sc, o, None) for s, sc, o in [
        ("coulomb_friction:F=100", "bump", {}),
        ("coulomb_friction:F=250", "iso8608", {"v_kmh": 50}),
        ("asymmetric_damping:c_rebound=2000,c_compression=800", "bump", {}),
        ("asymmetric_damping:c_rebound=1800,c_compression=1100", "iso8608", {"v_kmh": 50}),
        ("quadratic_damping:c_quad=1500", "bump", {}),
        ("quadratic_damping:c_quad=3000", "curb", {"h": 0.08}),
        ("progressive_spring:k_cubic=3e6", "bump", {}),
        ("progressive_spring:k_cubic=5e6", "iso8608", {"v_kmh": 60, "road_class": "D"}),
        ("bump_stop:gap=0.02,k_stop=100000", "bump", {}),
        ("bump_stop:gap=0.03,k_stop=60000", "curb", {"h": 0.12}),
        ("tire_liftoff", "curb", {"h": -0.3}),
        ("tire_liftoff", "bump", {"h": -0.3, "v_kmh": 30}),
        ("sensor_delay:channels=x_dot,delay_s=0.01", "bump", {}),
        ("sensor_delay:channels=x+x_dot,delay_s=0.015", "iso8608", {"v_kmh": 50}),
        ("sensor_offset:channel=x,offset=0.003", "bump", {}),
        ("sensor_offset:channel=x_dot,offset=0.01", "curb", {"h": 0.05}),
    ]] + [("none", [], "bump", {}, None), ("9 Hz body shake", [], "bump", {}, _shake("quarter1"))],
    "half4": [(s, [s], sc, o, None) for s, sc, o in [
        ("coulomb_friction:F=150", "bump", {}),
        ("coulomb_friction:F=200", "curb", {"h": 0.08}),
        ("quadratic_damping:c_quad=2000", "bump", {}),
        ("quadratic_damping:c_quad=3000", "iso8608", {"v_kmh": 50}),
        ("progressive_spring:k_cubic=3e6", "bump", {}),
        ("progressive_spring:k_cubic=5e6", "iso8608", {"v_kmh": 60, "road_class": "D"}),
        ("bump_stop:gap=0.02,k_stop=200000", "bump", {}),
        ("bump_stop:gap=0.015,k_stop=150000", "curb", {"h": 0.12}),
        ("tire_liftoff", "curb", {"h": -0.1}),
        ("tire_liftoff", "bump", {"h": 0.15, "v_kmh": 40}),
        ("sensor_delay:channels=x1+x1_dot,delay_s=0.008", "bump", {}),
        ("sensor_delay:channels=x2,delay_s=0.015", "iso8608", {"v_kmh": 50}),
        ("sensor_delay:channels=delta+delta_dot,delay_s=0.01", "curb", {"h": 0.05}),
        ("sensor_offset:channel=delta,offset=0.002", "bump", {}),
        ("sensor_offset:channel=x2,offset=-0.002", "curb", {"h": 0.05}),
    ]] + [
        ("front strut: coulomb_friction:F=200", [_in("front strut", "coulomb_friction:F=200")],
         "bump", {}, None),
        ("rear strut: asymmetric_damping:c_rebound=3400,c_compression=1400",
         [_in("rear strut", "asymmetric_damping:c_rebound=3400,c_compression=1400")], "bump", {}, None),
        ("asymmetric dampers front (2571/1029) and rear (3429/1371)",
         [_in("front strut", "asymmetric_damping:c_rebound=2571,c_compression=1029"),
          _in("rear strut", "asymmetric_damping:c_rebound=3429,c_compression=1371")], "bump", {}, None),
        ("none", [], "bump", {}, None),
        ("none", [], "curb", {}, None),
        ("9 Hz heave + 7 Hz pitch shake", [], "bump", {}, _shake("half4")),
    ],
    "full7": [(s, [s], sc, o, None) for s, sc, o in [
        ("coulomb_friction:F=150", "bump", {}),
        ("quadratic_damping:c_quad=2500", "iso8608", {"v_kmh": 50}),
        ("progressive_spring:k_cubic=5e6", "iso8608", {"v_kmh": 60, "road_class": "D"}),
        ("bump_stop:gap=0.02,k_stop=200000", "bump", {}),
        ("tire_liftoff", "curb", {"h": -0.1}),
        ("sensor_delay:channels=x3+x3_dot,delay_s=0.01", "iso8608", {"v_kmh": 50}),
        ("sensor_offset:channel=phi,offset=0.002", "iso8608", {"v_kmh": 50}),
    ]] + [
        ("front-left strut: coulomb_friction:F=200",
         [_in("front-left strut", "coulomb_friction:F=200")], "iso8608", {"v_kmh": 50}, None),
        ("none", [], "iso8608", {"v_kmh": 50}, None),
        ("none", [], "bump", {}, None),
    ],
    "quarter2": [(s, [s], sc, o, None) for s, sc, o in [
        ("coulomb_friction:F=80", "bump", {}),
        ("coulomb_friction:F=250", "iso8608", {"v_kmh": 50}),
        ("asymmetric_damping:c_rebound=1600,c_compression=640", "bump", {}),
        ("asymmetric_damping:c_rebound=1400,c_compression=900", "iso8608", {"v_kmh": 50}),
        ("quadratic_damping:c_quad=1500", "bump", {}),
        ("quadratic_damping:c_quad=4000", "curb", {"h": 0.08}),
        ("progressive_spring:k_cubic=1e8", "bump", {}),
        ("progressive_spring:k_cubic=3e8", "iso8608", {"v_kmh": 60, "road_class": "D"}),
        ("bump_stop:gap=0.01,k_stop=300000", "bump", {}),
        ("bump_stop:gap=0.02,k_stop=150000", "curb", {"h": 0.12}),
        ("tire_liftoff", "curb", {"h": -0.1}),
        ("sensor_delay:channels=x2+x2_dot,delay_s=0.008", "bump", {}),
        ("sensor_delay:channels=x1,delay_s=0.02", "iso8608", {"v_kmh": 50}),
        ("sensor_offset:channel=x1,offset=0.003", "bump", {}),
        ("sensor_offset:channel=x2,offset=-0.002", "curb", {"h": 0.05}),
    ]] + [("none", [], "bump", {}, None)],
}


def run_case(model: str, label: str, effects: Sequence[Any], scenario: str, opts: dict[str, Any],
             extra: Any) -> dict[str, Any]:
    """Diagnose one synthetic record; the row of the table as a dict (errors as fractions)."""
    p = TRUTH[model]
    meas = synthetic_record(model, effects, scenario, params=p, extra_force=extra, **opts)
    params = Parameters.for_model(get_model(model), fix={k: p[k] for k in FIXED[model]},
                                  init={k: 0.7 * p[k] for k in FREE[model]})
    t0 = time.perf_counter()
    out = diagnose(get_model(model), meas, params, maxfev=1200).to_json()
    seconds = time.perf_counter() - t0
    injected = [parse_effect(e) if isinstance(e, str) else e for e in effects]
    truth = dict(p)
    for e in injected:
        if e.name == "asymmetric_damping" and isinstance(e, PhysicalEffect):
            for site in e.sites(get_model(model), p):
                if site.c_name:
                    truth[site.c_name] = 0.5 * (e.values["c_rebound"] + e.values["c_compression"])
    eff = out["effect"]
    row: dict[str, Any] = {"model": model, "case": label, "scenario": scenario, "options": opts,
                           "selected": eff["name"] if eff else None, "seconds": seconds,
                           "verdict": out["evidence"]["verdict"],
                           "effect_sites": out["evidence"].get("effect_sites"),
                           "warnings": out["warnings"]}
    row["correct"] = (eff["name"] == injected[0].name) if (eff and len(injected) == 1) else (
        eff is None and len(injected) != 1)
    row["param_error"] = {}
    if eff and len(injected) == 1 and eff["name"] == injected[0].name:
        for k, v in injected[0].values.items():
            if isinstance(v, float):
                row["param_error"][k] = eff["params"][k] / v - 1.0
            else:
                row["param_error"][k] = "ok" if (sorted(v) if isinstance(v, list) else v) == (
                    sorted(eff["params"][k]) if isinstance(v, list) else eff["params"][k]) else "wrong"
        row["params"] = eff["params"]
    for which in ("baseline", "augmented"):
        row[f"base_error_{which}"] = max(abs(out[which]["params"][k] / truth[k] - 1.0) for k in FREE[model])
        row[f"rms_body_{which}"] = out[which]["rms_residual"][BODY[model]]
        row[f"cost_{which}"] = out[which]["cost"]
    b, a = out["baseline"]["rms_residual"], out["augmented"]["rms_residual"]
    row["rms_ratio_mean"] = float(np.mean([a[c] / b[c] for c in b]))
    return row


def _fmt_selected(r: dict[str, Any]) -> str:
    if r["selected"]:
        where = r["effect_sites"]
        n_struts = len(get_model(r["model"]).strut_sites(TRUTH[r["model"]]))
        only = (f" ({where[0]} only)" if where and len(where) == 1 and where[0].endswith("strut")
                and n_struts > 1 else "")
        return f"`{r['selected']}`{only}"
    v = r["verdict"]
    if "cannot be identified" in v:
        return "none: *not identifiable* (said so)"
    if "no candidate effect explains it" in v:
        return "none: *structured, unexplained*"
    return "none: *no missing effect*"


def _fmt_params(r: dict[str, Any]) -> str:
    if not r.get("params"):
        return "—"
    parts = []
    for k, e in r["param_error"].items():
        if isinstance(e, float):
            parts.append(f"{k} {r['params'][k]:.4g} ({e:+.1%})")
        else:
            parts.append(f"{k} {e}")
    return ", ".join(parts) or "(none)"


def markdown(rows: list[dict[str, Any]]) -> str:
    """The Markdown tables, one per model."""
    lines: list[str] = []
    for model in dict.fromkeys(r["model"] for r in rows):
        lines += [f"**{model}** (body channel `{BODY[model]}`; free {', '.join(FREE[model])})", "",
                  "| injected | road | selected | effect parameters (error) | base max error, "
                  "baseline → augmented | RMS `" + BODY[model] + "` (m) before → after | "
                  "mean RMS after/before | s |",
                  "|---|---|---|---|---|---|---|---|"]
        for r in (r for r in rows if r["model"] == model):
            road = r["scenario"] + ("" if not r["options"] else " " + ", ".join(
                f"{k}={v}" for k, v in r["options"].items()))
            lines.append(f"| {r['case']} | {road} | {_fmt_selected(r)} | {_fmt_params(r)} | "
                         f"{r['base_error_baseline']:.1%} → {r['base_error_augmented']:.1%} | "
                         f"{r['rms_body_baseline']:.3g} → {r['rms_body_augmented']:.3g} | "
                         f"{r['rms_ratio_mean']:.2f} | {r['seconds']:.1f} |")
        lines.append("")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Command line entry point (see the module docstring); returns the exit status."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", action="append", choices=sorted(CASES),
                    help="model(s) to run (repeatable; default quarter1 and half4)")
    ap.add_argument("--json", action="store_true", help="one JSON object per case instead of Markdown")
    args = ap.parse_args(argv)
    rows = []
    for model in args.model or ["quarter1", "half4"]:
        for label, effects, scenario, opts, extra in CASES[model]:
            r = run_case(model, label, effects, scenario, opts, extra)
            rows.append(r)
            sys.stderr.write(f"{model:8s} {label:60s} {scenario:8s} -> {r['selected']} "
                             f"({r['seconds']:.1f} s)\n")
            if args.json:
                print(json.dumps(r, default=float), flush=True)
    if not args.json:
        print(markdown(rows))
    bad = [r for r in rows if not r["correct"]]
    for r in bad:
        sys.stderr.write(f"unexpected: {r['model']} {r['case']} {r['scenario']}: {r['verdict']}\n")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
