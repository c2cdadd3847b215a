"""The seed's Taguchi orthogonal arrays and level values (Tables 3-6, SI units), verbatim.

L16: 4 levels, factors A-E; L27: 3 levels, columns A-K (the seed's unused L-N left out).
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

IntArray = NDArray[np.int64]

#: Table 3 - factor -> (name, unit, 4 level values)
L16_LEVELS: dict[str, tuple[str, str, tuple[float, float, float, float]]] = {
    "A": ("x0", "m", (0.05, 0.11, 0.23, 0.5)),
    "B": ("v0", "m/s", (0.05, 0.11, 0.23, 0.5)),
    "C": ("m", "kg", (250.0, 538.61, 1160.40, 2500.0)),
    "D": ("c", "N s/m", (100.0, 215.44, 464.16, 1000.0)),
    "E": ("k", "N/m", (100.0, 215.44, 464.16, 1000.0)),
}

#: Table 4 - experiment order of the L16-4 design (levels 1..4 of factors A-E)
L16_ARRAY: IntArray = np.array([
    [1, 1, 1, 1, 1],
    [1, 2, 2, 2, 2],
    [1, 3, 3, 3, 3],
    [1, 4, 4, 4, 4],
    [2, 1, 2, 3, 4],
    [2, 2, 1, 4, 3],
    [2, 3, 4, 1, 2],
    [2, 4, 3, 2, 1],
    [3, 1, 3, 4, 2],
    [3, 2, 4, 3, 1],
    [3, 3, 1, 2, 4],
    [3, 4, 2, 1, 3],
    [4, 1, 4, 2, 3],
    [4, 2, 3, 1, 4],
    [4, 3, 2, 4, 1],
    [4, 4, 1, 3, 2],
], dtype=np.int64)

#: Table 5 - factor -> (name, unit, 3 level values); L, M, N are unused (all 0 in the seed)
L27_LEVELS: dict[str, tuple[str, str, tuple[float, float, float]]] = {
    "A": ("x01", "m", (0.05, 0.16, 0.5)),
    "B": ("v01", "m/s", (0.05, 0.16, 0.5)),
    "C": ("x02", "m", (0.01, 0.03, 0.1)),
    "D": ("v02", "m/s", (0.01, 0.03, 0.1)),
    "E": ("m1", "kg", (10.0, 31.62, 100.0)),
    "F": ("c1", "N s/m", (100.0, 316.23, 1000.0)),
    "G": ("k1", "N/m", (100.0, 316.23, 1000.0)),
    "H": ("m2", "kg", (25.0, 79.06, 250.0)),
    "J": ("c2", "N s/m", (50.0, 158.11, 500.0)),
    "K": ("k2", "N/m", (50.0, 158.11, 500.0)),
}

#: Table 6 - experiment order of the L27-3 design, columns A-K (L-N unused, "-" in the seed)
L27_ARRAY: IntArray = np.array([
    [1, 1, 1, 1, 1, 1, 1, 1, 1, 1],
    [1, 1, 1, 1, 2, 2, 2, 2, 2, 2],
    [1, 1, 1, 1, 3, 3, 3, 3, 3, 3],
    [1, 2, 2, 2, 1, 1, 1, 2, 2, 2],
    [1, 2, 2, 2, 2, 2, 2, 3, 3, 3],
    [1, 2, 2, 2, 3, 3, 3, 1, 1, 1],
    [1, 3, 3, 3, 1, 1, 1, 3, 3, 3],
    [1, 3, 3, 3, 2, 2, 2, 1, 1, 1],
    [1, 3, 3, 3, 3, 3, 3, 2, 2, 2],
    [2, 1, 2, 3, 1, 2, 3, 1, 2, 3],
    [2, 1, 2, 3, 2, 3, 1, 2, 3, 1],
    [2, 1, 2, 3, 3, 1, 2, 3, 1, 2],
    [2, 2, 3, 1, 1, 2, 3, 2, 3, 1],
    [2, 2, 3, 1, 2, 3, 1, 3, 1, 2],
    [2, 2, 3, 1, 3, 1, 2, 1, 2, 3],
    [2, 3, 1, 2, 1, 2, 3, 3, 1, 2],
    [2, 3, 1, 2, 2, 3, 1, 1, 2, 3],
    [2, 3, 1, 2, 3, 1, 2, 2, 3, 1],
    [3, 1, 3, 2, 1, 3, 2, 1, 3, 2],
    [3, 1, 3, 2, 2, 1, 3, 2, 1, 3],
    [3, 1, 3, 2, 3, 2, 1, 3, 2, 1],
    [3, 2, 1, 3, 1, 3, 2, 2, 1, 3],
    [3, 2, 1, 3, 2, 1, 3, 3, 2, 1],
    [3, 2, 1, 3, 3, 2, 1, 1, 3, 2],
    [3, 3, 2, 1, 1, 3, 2, 3, 2, 1],
    [3, 3, 2, 1, 2, 1, 3, 1, 3, 2],
    [3, 3, 2, 1, 3, 2, 1, 2, 1, 3],
], dtype=np.int64)


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
