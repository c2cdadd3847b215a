#!/usr/bin/env bash
# Set up a virtual environment (.venv) with suspid, then run the main job's demo.
# Usage: bash tools/demo.sh [OUTDIR]   (default OUTDIR: out/demo)
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [[ ! -x .venv/bin/python ]]; then
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip >/dev/null
.venv/bin/python -m pip install --quiet -e .
export MPLBACKEND=Agg
exec .venv/bin/python tools/demo.py "${1:-out/demo}"
