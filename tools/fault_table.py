"""Frame loss -> parameter error: regenerate the fault table of ``docs/robustness.md``.

For each condition the simulated sensor node (:mod:`firmware_sim`) runs a quarter2 scenario
at 500 Hz with sensor noise and the given transmission fault; its frames go through the
estimator's :class:`~estimator.decode.listener.DecodeListener` (validation, counter
continuity, gap marking), are aligned on the 2 ms grid (lost samples stay NaN, road gaps
are bridged and reported) and identified with :func:`estimator.identify.fit` (``m1`` fixed
at its true value: with all six free the quarter car is only identifiable up to a common
scale). The error of every free parameter against the plant's truth is reported.

Usage::

    python tools/fault_table.py                      # the table in docs/robustness.md
    python tools/fault_table.py --duration 4 --seeds 1 --scenario bump   # quick look
    python tools/fault_table.py --json               # machine-readable

Columns: condition; frames sent / accepted / ``lost`` (inferred from counters) / rejected;
share of grid samples that are NaN; number of gap records; the largest and the mean
relative error of the free parameters (mean over seeds, worst seed in brackets).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from estimator.decode.listener import DecodeListener
from estimator.decode.log_input import aligned_to_measurement
from estimator.decode.replay import feed
from estimator.identify import OutputErrorProblem, Parameters, fit
from firmware_sim.faults import FaultConfig
from firmware_sim.node import NodeConfig, SensorNode
from suspid.models import get_model

#: (label, --fault specs) of the default table
CONDITIONS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("none", ()),
    ("random 1 %", ("loss=0.01",)),
    ("random 2 %", ("loss=0.02",)),
    ("random 5 %", ("loss=0.05",)),
    ("random 10 %", ("loss=0.10",)),
    ("bursts 2/s x 20 ms (~4 %)", ("burst=2:0.02",)),
    ("bursts 1/s x 100 ms (~9 %)", ("burst=1:0.1",)),
)

#: channels the node sends (body and wheel displacement and velocity, road)
CHANNELS = ["x1", "x2", "x1_dot", "x2_dot", "r", "r_dot"]


@dataclass
class Row:
    """One condition of the table, over all seeds."""

    label: str
    faults: tuple[str, ...]
    sent: int = 0
    accepted: int = 0
    lost: int = 0
    rejected: int = 0
    nan_share: float = 0.0
    gaps: int = 0
    max_err: list[float] = field(default_factory=list)
    mean_err: list[float] = field(default_factory=list)
    errors: dict[str, list[float]] = field(default_factory=dict)
    seconds: float = 0.0


def run_condition(faults: Sequence[str], *, scenario: str = "random", duration: float = 10.0,
                  seed: int = 0, maxfev: int | None = None,
                  restarts: int = 2) -> dict[str, object]:
    """Simulate, decode and identify one run.

    Parameters
    ----------
    faults : sequence of str
        ``--fault`` specs (see :mod:`firmware_sim.faults`).
    scenario : str
        Node scenario (``random`` = ISO 8608 class C road at 50 km/h, ``bump``, ...).
    duration : float
        Record length (s).
    seed : int
        Seed of road, noise and faults.
    maxfev : int, optional
        Evaluation budget of the fit.
    restarts : int
        Nelder-Mead restarts.

    Returns
    -------
    dict
        ``sent``, ``frames`` (decoder stats), ``nan_share``, ``gaps``, ``errors``
        (free parameter -> relative error), ``truth``, ``params``, ``seconds``.
    """
    t0 = time.perf_counter()
    model = get_model("quarter2")
    cfg = NodeConfig(model="quarter2", scenario=scenario, duration=duration, rate=500.0,
                     speed=0.0, channels=list(CHANNELS), seed=seed,
                     faults=FaultConfig.parse(faults, CHANNELS))
    node = SensorNode(cfg)
    listener = DecodeListener(model, node.db, capacity=1 << 14, growable=True)
    sent = feed(listener, node.frames())
    al = listener.aligned()
    meas = aligned_to_measurement(al, model, f"{scenario}:{','.join(faults) or 'none'}")
    truth = dict(node.truth(0.0))
    nan = np.concatenate([np.isnan(v) for k, v in al.values.items() if k in meas.measured])
    params = Parameters.for_model(model, fix={"m1": truth["m1"]})
    problem = OutputErrorProblem(model, meas, cost="sse", x0="estimate")
    result, _ = fit(problem, params, restarts=restarts, maxfev=maxfev)
    errors = {k: abs(result.params[k] / truth[k] - 1.0) for k in truth if k != "m1"}
    return {"sent": sent, "frames": listener.frame_stats(), "nan_share": float(nan.mean()),
            "gaps": len([g for g in al.gaps if g.channel in meas.measured]),
            "errors": errors, "truth": truth, "params": dict(result.params),
            "seconds": time.perf_counter() - t0}


def build_table(conditions: Sequence[tuple[str, tuple[str, ...]]] = CONDITIONS, *,
                scenario: str = "random", duration: float = 10.0, seeds: int = 2,
                maxfev: int | None = None, restarts: int = 2) -> list[Row]:
    """Run every condition for ``seeds`` seeds (see :func:`run_condition`)."""
    rows = []
    for label, faults in conditions:
        row = Row(label, tuple(faults))
        for seed in range(seeds):
            r = run_condition(faults, scenario=scenario, duration=duration, seed=seed,
                              maxfev=maxfev, restarts=restarts)
            fr = r["frames"]
            row.sent += int(r["sent"])
            row.accepted += int(fr["accepted"])
            row.lost += int(fr["lost"])
            row.rejected += int(sum(fr["rejected"].values()))
            row.nan_share += float(r["nan_share"]) / seeds
            row.gaps += int(r["gaps"])
            errs = r["errors"]
            row.max_err.append(max(errs.values()))
            row.mean_err.append(float(np.mean(list(errs.values()))))
            for k, v in errs.items():
                row.errors.setdefault(k, []).append(v)
            row.seconds += float(r["seconds"])
        rows.append(row)
    return rows


def format_table(rows: Sequence[Row]) -> str:
    """Markdown table of :func:`build_table` rows."""
    names = list(rows[0].errors) if rows else []
    head = ("| condition | frames sent | accepted | lost (counted) | rejected | NaN samples "
            "| gaps | " + " | ".join(f"{n} err" for n in names) + " | max err | mean err |")
    sep = "|" + "---|" * (8 + len(names) + 1)
    lines = [head, sep]
    for r in rows:
        per = " | ".join(f"{100 * np.mean(r.errors[n]):.2f} %" for n in names)
        lines.append(f"| {r.label} | {r.sent} | {r.accepted} | {r.lost} | {r.rejected} | "
                     f"{100 * r.nan_share:.1f} % | {r.gaps} | {per} | "
                     f"{100 * np.mean(r.max_err):.2f} % ({100 * max(r.max_err):.2f}) | "
                     f"{100 * np.mean(r.mean_err):.2f} % |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Command line of the tool."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default="random", help="node scenario (default random road)")
    ap.add_argument("--duration", type=float, default=10.0, help="record length s (default 10)")
    ap.add_argument("--seeds", type=int, default=2, help="seeds per condition (default 2)")
    ap.add_argument("--maxfev", type=int, default=None, help="fit evaluation budget")
    ap.add_argument("--restarts", type=int, default=2, help="Nelder-Mead restarts (default 2)")
    ap.add_argument("--json", action="store_true", help="print JSON instead of markdown")
    a = ap.parse_args(argv)
    rows = build_table(scenario=a.scenario, duration=a.duration, seeds=a.seeds,
                       maxfev=a.maxfev, restarts=a.restarts)
    if a.json:
        json.dump([r.__dict__ for r in rows], sys.stdout, indent=1)
        sys.stdout.write("\n")
    else:
        print(f"quarter2, scenario {a.scenario}, {a.duration:g} s at 500 Hz, {a.seeds} seed(s), "
              f"m1 fixed; wall {sum(r.seconds for r in rows):.0f} s")
        print(format_table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
