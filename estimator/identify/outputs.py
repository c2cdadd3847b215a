"""What a linear model predicts for a record's channels: the output maps of motions and
ride heights, and the check that a record's values are in SI units."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from suspid.errors import InputError
from suspid.models.base import FloatArray, SuspensionModel
from suspid.simulate import (ride_height_maps)


@dataclass
class Prediction:
    """A model prediction on the measured channels."""

    Y: FloatArray  # (N, p) predicted channels
    x0: FloatArray  # initial state used (n,)
    residual: FloatArray  # (N, p) measured - predicted, NaN where missing


def channel_kinds(coords: Sequence[str], channels: Sequence[str]) -> list[tuple[int, int]]:
    """``(coordinate index, derivative order)`` of each channel name (``x1_dot`` -> (i, 1))."""
    idx = {c: i for i, c in enumerate(coords)}
    return [(idx[c.split("_")[0]], 2 if c.endswith("_ddot") else (1 if c.endswith("_dot") else 0))
            for c in channels]


def output_maps(kinds: Sequence[tuple[int, int]], A: FloatArray, B: FloatArray, nq: int
                ) -> tuple[FloatArray, FloatArray]:
    """Output maps ``y = Cm x + Dm u`` of channels given by :func:`channel_kinds`.

    Positions and velocities are rows of the identity on the state ``x = [q, q']``;
    an acceleration is the model's row ``q'' = A[nq + i] x + B[nq + i] u``.
    """
    Cm = np.zeros((len(kinds), A.shape[0]))
    Dm = np.zeros((len(kinds), B.shape[1]))
    for j, (i, order) in enumerate(kinds):
        if order == 0:
            Cm[j, i] = 1.0
        elif order == 1:
            Cm[j, nq + i] = 1.0
        else:
            Cm[j] = A[nq + i]
            Dm[j] = B[nq + i]
    return Cm, Dm


def ride_height_rows(model: SuspensionModel, channels: Sequence[str], p: Mapping[str, float]
                     ) -> tuple[FloatArray, FloatArray]:
    """Output maps ``y = C x + D u`` of ride-height channels (``d``, ``d2_dot``, ...).

    A strut's extension ``g . q + gr . r`` (m) reads the positions and the roads, its rate
    ``g . q' + gr . r'`` (m/s) the velocities and the road rates (``g``, ``gr`` of
    ``model.strut_sites(p)``, so the geometry in ``p`` counts).

    Returns
    -------
    C : ndarray, shape (len(channels), n_states)
    D : ndarray, shape (len(channels), 2 n_roads)
    """
    G, Gr = ride_height_maps(model, p)
    nq, nr = G.shape[1], Gr.shape[1]
    index = {d: i for i, d in enumerate(model.ride_heights)}
    C = np.zeros((len(channels), 2 * nq))
    D = np.zeros((len(channels), 2 * nr))
    for j, c in enumerate(channels):
        rate = c.endswith("_dot")
        i = index[c[:-4] if rate else c]
        C[j, nq * rate:nq * (rate + 1)] = G[i]
        D[j, nr * rate:nr * (rate + 1)] = Gr[i]
    return C, D


def check_magnitudes(source: str, columns: Mapping[str, FloatArray]) -> None:
    """Raise :class:`~suspid.errors.InputError` naming the first column whose sum of squares
    overflows (values near 1e200 and up, a unit slip): no cost can be formed on it.

    Parameters
    ----------
    source : str
        Where the record came from (for the message).
    columns : mapping
        Column name -> values (NaN for missing samples are skipped).
    """
    for name, col in columns.items():
        c = np.nan_to_num(np.asarray(col, dtype=float), nan=0.0)
        with np.errstate(over="ignore"):
            ok = np.isfinite(float(c @ c))
        if not ok:
            big = float(np.max(np.abs(c)))
            raise InputError(f"{source}: column {name!r}: values up to {big:.3g} "
                             "overflow the sum of squares; expected SI units (m, m/s, m/s^2, rad)")
