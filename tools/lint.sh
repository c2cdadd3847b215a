#!/usr/bin/env bash
# The habits CI keeps: ruff (lint), mypy (types) and import-linter (layers point down, no
# cycles). Configuration: pyproject.toml. Usage: bash tools/lint.sh  (after tools/test.sh set up .venv)
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-.venv/bin/python}
echo "lint: ruff ..." >&2
"$PY" -m ruff check --quiet suspid estimator firmware_sim tools tests
echo "lint: import-linter ..." >&2
.venv/bin/lint-imports --no-cache >/tmp/suspid-lint-imports.log 2>&1 || { cat /tmp/suspid-lint-imports.log >&2; exit 1; }
echo "lint: mypy ..." >&2
"$PY" -m mypy --no-error-summary --cache-dir="${MYPY_CACHE_DIR:-.mypy_cache}"
echo "lint: ruff, import-linter, mypy clean" >&2
