#!/usr/bin/env bash
# Set up a virtual environment (.venv) with suspid and its test tools, then run the tests.
# Usage: bash tools/test.sh [pytest args...]
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
# Debian packages the tests use (tools/system-packages.txt), installed when missing and root
bash tools/system_deps.sh
if [[ ! -x .venv/bin/python ]]; then
  "$PY" -m venv .venv
fi
# pip's and setuptools' chatter goes to .venv/install.log, shown only if the install fails
install() { .venv/bin/python -m pip install --quiet "$@" >>.venv/install.log 2>&1 || { cat .venv/install.log >&2; exit 1; }; }
: >.venv/install.log
echo "setting up .venv (pip log: .venv/install.log) ..." >&2
install --upgrade pip
install -e ".[test]"
export MPLBACKEND=Agg
# small matrices: BLAS threads only add contention (see suspid/cli/__init__.py)
export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-1} OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}
# the linter, the import contract and the type checker (pyproject.toml) must pass too
bash tools/lint.sh
exec .venv/bin/python -m pytest "$@"
