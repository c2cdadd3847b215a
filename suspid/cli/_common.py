"""Option parsing shared by several subcommands (model, parameters, input files)."""
from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any, Mapping

import numpy as np

from suspid.cli._can import add_can_arguments
from suspid.errors import UsageError
from suspid.models import MODELS, SuspensionModel
from suspid.models.base import FloatArray

#: what ``--model`` help says of the bundled models (a plug-in model is listed by name)
MODEL_HELP = {"quarter1": "1 DOF, eq. 1", "quarter2": "2 DOF, eqs. 2-3",
              "half4": "4 DOF half car, eqs. 4-7", "full7": "7 DOF full car"}


def add_model_option(p: argparse.ArgumentParser, required: bool = True) -> None:
    """``--model``, its help naming every registered model (the choices)."""
    p.add_argument("--model", required=required, choices=list(MODELS),
                   help="suspension model: " + ", ".join(
                       f"{n} ({MODEL_HELP[n]})" if n in MODEL_HELP else n for n in MODELS))


def add_param_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE",
                   help="hold a parameter at a known value (SI), e.g. --fix m1=275; repeatable")
    p.add_argument("--init", action="append", default=[], metavar="NAME=VALUE",
                   help="starting guess of a free parameter (SI); free parameters without it "
                        "start from the model's documented defaults; repeatable")


def add_input_options(p: argparse.ArgumentParser, command: str) -> None:
    """``--input``, ``--dbc``, ``--map`` and ``--config`` of a command reading one record."""
    p.add_argument("--input", required=True, metavar="PATH",
                   help="measurement CSV, or a CAN log (.log candump -L, .asc, .blf, .trc, .mf4) "
                        "decoded with --dbc")
    p.add_argument("--dbc", metavar="PATH", default=None,
                   help="DBC for CAN-log input (default: the bundled dbc/suspension.dbc)")
    add_can_arguments(p, command)


def positive_int(text: str) -> int:
    """argparse ``type``: an integer >= 1 (argparse turns the ValueError into a usage error)."""
    try:
        v = int(text)
    except ValueError:
        v = 0
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}")
    return v


#: smallest magnitude (SI) of a non-zero ``NAME=VALUE`` parameter: no mass, inertia, stiffness,
#: damping or length of a vehicle comes near it, so a smaller one is a typo or a unit slip
MIN_PARAM_MAGNITUDE = 1e-9


def parse_assignments(items: list[str], option: str) -> dict[str, float]:
    """Parse ``NAME=VALUE`` strings (``--fix``, ``--init``, ``--nominal``, ``--param``) into a
    dict: finite numbers, non-zero ones at least ``MIN_PARAM_MAGNITUDE`` (UsageError naming the
    bad item)."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise UsageError(f"{option} {item!r}: expected NAME=VALUE")
        try:
            v = float(value)
        except ValueError:
            raise UsageError(f"{option} {item!r}: expected a number after '=', got {value!r}") from None
        if not math.isfinite(v):
            raise UsageError(f"{option} {item!r}: expected a finite number, got {value!r}")
        if v != 0.0 and abs(v) < MIN_PARAM_MAGNITUDE:
            what = "a subnormal number" if abs(v) < sys.float_info.min else "absurdly small"
            raise UsageError(f"{option} {name}: expected a value of magnitude at least "
                             f"{MIN_PARAM_MAGNITUDE:g} in SI units (kg, kg m^2, N/m, N s/m, m), "
                             f"got {value.strip()} ({what})")
        if name in out:
            raise UsageError(f"{option} {name} given twice")
        out[name] = v
    return out


def parse_state(text: str, n: int, option: str) -> FloatArray:
    """A state vector given as ``n`` comma-separated finite numbers (``[q..., q_dot...]``, SI;
    UsageError otherwise)."""
    parts = text.split(",")
    try:
        v = np.array([float(s) for s in parts])
    except ValueError:
        raise UsageError(f"{option} {text!r}: expected {n} comma-separated numbers") from None
    if v.size != n:
        raise UsageError(f"{option}: expected {n} values [q..., q_dot...], got {v.size}")
    bad = np.flatnonzero(~np.isfinite(v))
    if bad.size:
        raise UsageError(f"{option} {text!r}: value {int(bad[0]) + 1} is {parts[int(bad[0])].strip()!r}; "
                         "expected a finite number")
    return v


def print_json(obj: Any) -> None:
    """Print one JSON object on stdout (NaN/inf become null)."""
    def clean(o: Any) -> Any:
        if isinstance(o, float):
            return o if math.isfinite(o) else None
        if isinstance(o, dict):
            return {k: clean(v) for k, v in o.items()}
        if isinstance(o, (list, tuple)):
            return [clean(v) for v in o]
        return o

    sys.stdout.write(json.dumps(clean(obj)) + "\n")
    sys.stdout.flush()


#: the lengths (m) of a vehicle's or test rig's geometry; a value outside is a unit slip (mm).
#: Masses, stiffnesses and damping rates get no range: the seed's designs span orders of magnitude
LENGTH_RANGE_M = (0.01, 20.0)


def implausible_values(model: SuspensionModel, values: Mapping[str, float],
                       option: str) -> list[str]:
    """One warning per length in ``values`` (SI, from ``option``) outside ``LENGTH_RANGE_M``."""
    lo, hi = LENGTH_RANGE_M
    out: list[str] = []
    for name, v in values.items():
        spec = model.spec(name)
        if spec.kind == "length" and v > 0 and not lo <= v <= hi:
            out.append(f"{option} {name}={v:g} {spec.unit} ({spec.description}) is outside "
                       f"{lo:g}..{hi:g} m, the lengths of vehicles and test rigs (default "
                       f"{spec.default:g} m): a value in mm or cm? suspid takes SI units")
    return out


def assignment_warnings(args: argparse.Namespace, model: SuspensionModel) -> list[str]:
    """:func:`implausible_values` of ``--fix``, ``--init`` and ``--nominal``."""
    out: list[str] = []
    for option in ("--fix", "--init", "--nominal"):
        items = getattr(args, option[2:], None)
        if items:
            out += implausible_values(model, parse_assignments(items, option), option)
    return out
