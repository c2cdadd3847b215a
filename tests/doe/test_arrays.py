"""The Taguchi arrays and level values are the seed's Tables 3-6."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from estimator.doe.arrays import L16_ARRAY, L16_LEVELS, L27_ARRAY, L27_LEVELS, IntArray

SEED = Path(__file__).resolve().parents[2].parent / "shared" / "seeds" / "000_62c11f2ef4afa30d.txt"


def is_orthogonal(array: IntArray) -> bool:
    """``True`` if every pair of columns (levels from 1) shows every level pair equally often."""
    runs, k = array.shape
    levels = int(array.max())
    expected = runs / levels ** 2
    for i in range(k):
        for j in range(i + 1, k):
            counts = np.zeros((levels, levels), dtype=int)
            np.add.at(counts, (array[:, i] - 1, array[:, j] - 1), 1)
            if not np.all(counts == expected):
                return False
    return True


def _table_rows(text: str, caption: str, ncols: int) -> np.ndarray:
    """Integer rows of the table that follows ``caption`` in the seed's text."""
    start = text.index(caption)
    rows = []
    for line in text[start:].splitlines()[1:]:
        cells = line.split()
        if not cells:
            continue
        if re.fullmatch(r"\d+", cells[0]) and len(cells) >= ncols + 1:
            rows.append([int(c) for c in cells[1:ncols + 1]])
        elif rows:
            break
    return np.array(rows)


@pytest.fixture(scope="module")
def seed_text() -> str:
    if not SEED.is_file():
        pytest.skip(f"seed paper not found at {SEED}")
    return SEED.read_text(encoding="utf-8")


def test_l16_equals_seed_table4(seed_text: str) -> None:
    rows = _table_rows(seed_text, "Table 4.** Order of experiments", 5)
    assert rows.shape == (16, 5)
    np.testing.assert_array_equal(rows, L16_ARRAY)


def test_l27_equals_seed_table6(seed_text: str) -> None:
    rows = _table_rows(seed_text, "Table 6.** Order of experiments", 10)
    assert rows.shape == (27, 10)
    np.testing.assert_array_equal(rows, L27_ARRAY)


def test_level_values_equal_seed_tables_3_and_5(seed_text: str) -> None:
    def values(caption: str, label: str) -> list[float]:
        start = seed_text.index(caption)
        for line in seed_text[start:].splitlines():
            if line.startswith(label):
                return [float(v) for v in line.split()[len(label.split()):]]
        raise AssertionError(f"{label} row not found")

    for k in range(4):
        got = values("Table 3.** Values for each level", f"Value {k + 1}")
        assert got == [L16_LEVELS[f][2][k] for f in "ABCDE"]
    for k in range(3):
        got = values("Table 5.** Values for each level", f"Val{k + 1}")
        assert got[:10] == [L27_LEVELS[f][2][k] for f in "ABCDEFGHJK"]


@pytest.mark.parametrize("array,levels", [(L16_ARRAY, 4), (L27_ARRAY, 3)])
def test_arrays_are_balanced_orthogonal_arrays(array: np.ndarray, levels: int) -> None:
    assert is_orthogonal(array)
    for col in array.T:
        assert np.bincount(col)[1:].tolist() == [array.shape[0] // levels] * levels


def test_is_orthogonal_detects_a_broken_array() -> None:
    broken = L27_ARRAY.copy()
    broken[0, 5], broken[1, 5] = broken[1, 5], broken[0, 5]
    assert not is_orthogonal(broken)


@pytest.mark.parametrize("levels", [L16_LEVELS, L27_LEVELS])
def test_parameter_levels_are_geometric(levels: dict) -> None:
    """Physical-parameter levels are log-spaced (ratio 10^(1/3) or 10^(1/2)) to 4 digits."""
    for name, unit, vals in levels.values():
        if unit in ("m", "m/s"):
            continue
        r = np.diff(np.log10(vals))
        assert np.allclose(r, r[0], atol=2e-4), name
