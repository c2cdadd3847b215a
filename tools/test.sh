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
# The tests run in four steps. The main suite: the tests that only compute, in parallel
# (pytest-xdist: one worker per core, at most 4; TEST_WORKERS=N sets the number), minus those
# marked slow. The slow ones (physics sweeps, long end-to-end runs: 10 s and more each) run
# next in the same way, as their own step bounded by SLOW_LIMIT seconds (default 1200: a step
# that overruns fails). Then the tests marked realtime (paced in wall-clock time: live buses,
# ptys, nodes with --speed) one after another on an otherwise idle suite, so that the
# parallel load cannot make them late.
# The SocketCAN tests (marker socketcan: vcan0 and can-utils) run in one more pytest through
# tools/vcan_bench.sh: natively where the kernel has SocketCAN, otherwise in one User-Mode
# Linux guest. pytest's status 5 (no test selected, e.g. when the arguments name tests of
# one step only) counts as success as long as some step ran tests.
# (GNU nproc honours OMP_NUM_THREADS, set to 1 above: count the cores without it)
cores=$(env -u OMP_NUM_THREADS -u OMP_THREAD_LIMIT nproc)
workers=${TEST_WORKERS:-$(( cores < 4 ? cores : 4 ))}
set +e
.venv/bin/python -m pytest -m "not socketcan and not realtime and not slow" -n "$workers" "$@"
parallel=$?
timeout --signal=INT --kill-after=30 "${SLOW_LIMIT:-1200}" \
  .venv/bin/python -m pytest -m "slow and not socketcan and not realtime" -n "$workers" "$@"
slow=$?
if [[ $slow -eq 124 || $slow -eq 137 ]]; then   # timeout: INT sent, then KILL
  echo "tools/test.sh: the slow step overran its ${SLOW_LIMIT:-1200} s bound" >&2
fi
.venv/bin/python -m pytest -m "realtime and not socketcan" "$@"
paced=$?
bash tools/vcan_bench.sh .venv/bin/python -m pytest -m socketcan "$@"
bench=$?
set -e
status=5
for s in "$parallel" "$slow" "$paced" "$bench"; do
  if [[ $s -ne 0 && $s -ne 5 ]]; then exit "$s"; fi
  if [[ $s -eq 0 ]]; then status=0; fi
done
exit "$status"
