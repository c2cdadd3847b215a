"""The product code stays small: at most 28,000 lines in all, at most 900 in any one module.

Counted as ``cat $(git ls-files 'suspid/*.py' 'estimator/*.py' 'firmware_sim/*.py') | wc -l``
counts them: every line of every module of the three packages (docstrings, comments and blank
lines included). Tests, tools and docs are not product code.
"""
from __future__ import annotations

from pathlib import Path

from tests.conftest import REPO

PACKAGES = ("suspid", "estimator", "firmware_sim")
#: most lines of product code in all
MAX_TOTAL = 28_000
#: most lines of one module
MAX_MODULE = 900


def _line_counts() -> dict[Path, int]:
    return {p.relative_to(REPO): len(p.read_bytes().splitlines())
            for pkg in PACKAGES for p in sorted((REPO / pkg).rglob("*.py"))}


def test_no_module_is_over_900_lines() -> None:
    counts = _line_counts()
    assert len(counts) > 100
    over = {str(p): n for p, n in counts.items() if n > MAX_MODULE}
    assert not over, f"modules over {MAX_MODULE} lines: {over}"


def test_product_code_is_at_most_28000_lines() -> None:
    total = sum(_line_counts().values())
    assert total > 10_000
    assert total <= MAX_TOTAL, f"product code is {total} lines, over {MAX_TOTAL}"
