#!/usr/bin/env bash
# Set up a virtual environment (.venv) with suspid, then run the main job's demo.
# Usage: bash tools/demo.sh [OUTDIR]   (default OUTDIR: out/demo)
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [[ ! -x .venv/bin/python ]]; then
  "$PY" -m venv .venv
fi
# pip's and setuptools' chatter goes to .venv/install.log, shown only if the install fails
install() { .venv/bin/python -m pip install --quiet "$@" >>.venv/install.log 2>&1 || { cat .venv/install.log >&2; exit 1; }; }
: >.venv/install.log
echo "setting up .venv (pip log: .venv/install.log) ..." >&2
install --upgrade pip
install -e .
export MPLBACKEND=Agg
exec .venv/bin/python tools/demo.py "${1:-out/demo}"
