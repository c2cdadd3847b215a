"""``suspid simulate``: simulate a model under a scenario and write a measurement CSV."""
from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

import numpy as np

from suspid.cli._can import add_config_option
from suspid.cli._config import load_config
from suspid.cli._common import add_model_option, parse_assignments, parse_state, print_json
from suspid.cli._lazy import lazy_names
from suspid.errors import UsageError
from suspid.excitation import SCENARIOS, make_scenario, measured_road
from suspid.io.csvio import read_measurement, write_measurement
from suspid.models import get_model
from suspid.models.base import CHANNEL_SETS, SuspensionModel
from suspid.simulate import simulate, uniform_step

if TYPE_CHECKING:
    from estimator.identify.regrid import to_uniform_grid
    from suspid.plots import plot_channels
else:
    to_uniform_grid, = lazy_names("estimator.identify.regrid", "to_uniform_grid")
    plot_channels, = lazy_names("suspid.plots", "plot_channels")

#: an injected effect changing no channel by more than this fraction of its RMS is never engaged
INACTIVE_EFFECT = 1e-6


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("simulate", help="simulate a model and write a measurement CSV",
                       description="Simulate a suspension model exactly (modal solution, "
                                   "first-order-hold road) and write the contract's CSV.")
    add_model_option(p)
    p.add_argument("--scenario", choices=SCENARIOS, default="bump",
                   help="initial (state away from equilibrium), curb, bump (speed bump) or "
                        "iso8608 (random road)")
    p.add_argument("--road", default=None, metavar="CSV",
                   help="simulate over a measured road instead of a scenario's: a CSV with 't' "
                        "and the model's road columns (r; half4: r1 and r2, or r1 alone with the "
                        "rear delayed by (a1 + a2) / --speed; full7: r1..r4, or the front r1, r2 "
                        "with the rear ones delayed), optional _dot columns; its t is "
                        "the time grid (--duration/--fs are not used)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="true parameter value (SI); others use the model defaults; repeatable")
    p.add_argument("--duration", type=float, default=5.0, help="record length in s (default 5)")
    p.add_argument("--fs", type=float, default=1000.0, help="sample rate in Hz (default 1000)")
    p.add_argument("--speed", type=float, default=20.0, help="vehicle speed in km/h (default 20)")
    add_config_option(p, "simulate")
    p.add_argument("--x0", default=None, metavar="V1,V2,...",
                   help="initial state [q..., q_dot...] (default: the seed's for 'initial', rest otherwise)")
    p.add_argument("--noise", type=float, default=0.0,
                   help="Gaussian noise, std as a fraction of each channel's std (seed: 0.1-0.5)")
    p.add_argument("--seed", type=int, default=0, help="random seed for noise and random roads")
    p.add_argument("--channels", default=None,
                   help="comma-separated channels to write (default: positions and velocities), "
                        "ride heights (d, d_dot; d1..d4) included, or a named set: 'production' "
                        "(body accelerations and ride heights), 'accelerometers' (every "
                        "coordinate's _ddot); the road columns are written unless a named set "
                        "is given (then only road columns listed among the channels)")
    p.add_argument("--effect", action="append", default=[], metavar="NAME[:key=val,...]",
                   help="inject an effect the declared model lacks (undeclared; see suspid "
                        "diagnose), e.g. coulomb_friction:F=120, bump_stop:gap=0.01,k_stop=3e5, "
                        "tire_liftoff, sensor_delay:channels=x2+x2_dot,delay_s=0.008, "
                        "sensor_offset:channel=x1,offset=0.003; repeatable")
    p.add_argument("--out", required=True, metavar="CSV", help="output measurement CSV")
    p.add_argument("--plot", default=None, metavar="PNG", help="also plot the channels")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    return p


def select_channels(model: SuspensionModel, spec: str | None) -> tuple[list[str], list[str]]:
    """The measured channels (a named set expanded in place) and the road columns (every one
    unless a named set is given, else those listed) that ``--channels`` asks to write."""
    road_cols = [c for r in model.roads for c in (r, f"{r}_dot")]
    if not spec:
        return [c for c in model.channels if not c.endswith("_ddot")], road_cols
    valid = list(model.channels) + list(model.ride_height_channels)
    chans: list[str] = []
    listed: list[str] = []
    named = False
    bad = []
    for item in (c.strip() for c in spec.split(",")):
        if not item:
            continue
        if item in CHANNEL_SETS:
            named = True
            chans += model.channel_set(item)
        elif item in valid:
            chans.append(item)
        elif item in road_cols:
            listed.append(item)
        else:
            bad.append(item)
    if bad:
        raise UsageError(f"--channels: unknown channel(s) {', '.join(bad)} for {model.name}; "
                         f"expected any of {', '.join(valid + road_cols)} or a set "
                         f"({', '.join(CHANNEL_SETS)})")
    roads = [c for c in road_cols if c in listed] if named else road_cols
    return list(dict.fromkeys(chans)), roads


def run(args: argparse.Namespace) -> int:
    shape = load_config(args.config).table("simulate")
    model = get_model(args.model)
    params = model.defaults()
    given = parse_assignments(args.param, "--param")
    for k, v in given.items():
        model.spec(k)
        if v <= 0:
            raise UsageError(f"--param {k}={v}: expected a value > 0")
    params.update(given)
    x0 = parse_state(args.x0, model.n_states, "--x0") if args.x0 else None
    warnings: list[str] = []
    if not 0 <= args.noise < float("inf"):
        raise UsageError(f"--noise: expected a finite fraction >= 0, got {args.noise}")
    if args.road:
        given_road = read_measurement(args.road, model, require_measured=False)
        if args.effect:
            # the nonlinear simulation steps on a uniform grid: a jittered road is resampled
            given_road, note = to_uniform_grid(given_road)
            if note is not None:
                warnings.append(f"{note}; the simulation and --out are on that grid")
                sys.stderr.write(f"warning: {warnings[-1]}\n")
        t = given_road.t
        road = measured_road(model, t, given_road.road, params, args.speed, source=args.road)
        x0 = np.zeros(model.n_states) if x0 is None else x0
        scenario = f"measured road {args.road}"
    else:
        t, road, x0 = make_scenario(model, args.scenario, duration=args.duration, fs=args.fs,
                                    params=params, h=shape.get("height_m", 0.1),
                                    l=shape.get("length_m", 3.0), v_kmh=args.speed,
                                    t0=shape.get("t0_s", 0.5),
                                    road_class=shape.get("road_class", "C"), seed=args.seed, x0=x0)
        scenario = args.scenario
    if args.effect and args.road and uniform_step(t) is None:
        d = np.diff(t)
        raise UsageError(f"--effect with --road {args.road}: the nonlinear simulation steps on a "
                         f"uniform time grid; the road's time steps range from {float(d.min()):.6g} "
                         f"to {float(d.max()):.6g} s, more than a quarter step of jitter (resample "
                         "the road, or simulate without --effect)")
    if args.effect:
        # suspid.effects is slow to import; only runs with --effect need it
        from suspid.effects import inject  # noqa: PLC0415
        injection = inject(model, args.effect)
        injection.check_record(t)
        out = injection.simulate(params, t, road, x0)
        changes = injection.influence(params, t, road, x0, combined=out)
        for i, (spec, change) in enumerate(zip(args.effect, changes)):
            if change < INACTIVE_EFFECT:
                note = (f"--effect {spec} changes no channel on this record by more than "
                        f"{INACTIVE_EFFECT:g} of its RMS (largest change {change:.2g}): the record "
                        "never engages it" + ("; check the values and their units (SI)"
                                              if injection.effects[i].numeric_names else ""))
                warnings.append(note)
                sys.stderr.write(f"warning: {note}\n")
    else:
        out = simulate(model, params, t, road, x0)
    chans, roads = select_channels(model, args.channels)
    rng = np.random.default_rng(args.seed)
    cols: dict[str, np.ndarray] = {r: out[r] for r in roads} if road else {}
    for c in chans:
        y = out[c]
        if args.noise > 0:
            y = y + rng.standard_normal(y.size) * args.noise * np.std(y)
        cols[c] = y
    write_measurement(args.out, t, cols)
    if args.plot:
        plot_channels(model, t, {"simulated": cols}, args.plot, title=f"{model.name}: {scenario}")
    if args.json:
        print_json({"model": model.name, "scenario": scenario, "params": params,
                    "x0": [float(v) for v in x0], "samples": int(t.size), "out": args.out,
                    "channels": list(cols), "effects": list(args.effect), "warnings": warnings})
    return 0
