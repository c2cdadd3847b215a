"""``suspid encode``: a measurement CSV as the CAN log the sensor node would send."""
from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from suspid.can.formats import FORMATS
from suspid.cli._lazy import lazy_names
from suspid.models import MODELS

if TYPE_CHECKING:
    from suspid.can.dbc import load_dbc
    from suspid.can.encoder import encode_csv
else:
    load_dbc, = lazy_names("suspid.can.dbc", "load_dbc")
    encode_csv, = lazy_names("suspid.can.encoder", "encode_csv")


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``suspid encode``."""
    p = subparsers.add_parser(
        "encode", help="encode a measurement CSV as a CAN log (.log/.asc/.blf/.trc/.mf4)",
        description="Write the CAN log that the sensor node would transmit for the "
        "measurements of a CSV: per row an SN_Sync frame and the sensor frames of the "
        "model's message set (signals quantized as the DBC defines them, E2E counter and "
        "CRC), SN_Status at 10 Hz. Every frame is stamped with the row's t (+ --t0), so "
        "times read back from the log equal the CSV's. Log format by --out suffix: "
        + ", ".join(f"{s} ({n})" for s, n in FORMATS.items()) + ".")
    p.add_argument("--input", required=True, metavar="CSV", help="measurement CSV (see CONTRACT)")
    p.add_argument("--dbc", metavar="PATH", help="DBC (default: suspid's dbc/suspension.dbc)")
    p.add_argument("--out", required=True, metavar="PATH", help="CAN log to write")
    p.add_argument("--t0", type=float, default=0.0, metavar="SECONDS",
                   help="added to every timestamp (default 0)")
    p.add_argument("--model", choices=list(MODELS),
                   help="model of the CSV columns (default: inferred from the columns, the "
                        "most specific model that owns them all: x1/x2 without x, delta or "
                        "r1/r2 mean quarter2, phi/x3/x4/r3/r4 full7)")
    return p


def run(args: argparse.Namespace) -> int:
    """Encode; print a one-line summary on stdout and warnings on stderr."""
    db = load_dbc(args.dbc)
    res = encode_csv(args.input, args.out, db, args.model, args.t0)
    for ch, n in res.saturated.items():
        sys.stderr.write(f"warning: {args.input}: {n} sample(s) of {ch} outside the DBC range; "
                         "sent clamped with the Valid bit cleared\n")
    print(f"{args.out}: {res.frames} frames, {res.samples} samples, model {res.model}, "
          f"messages {' '.join(res.messages)} + SN_Status")
    return 0
