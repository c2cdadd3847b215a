"""Seed-style figures: measured vs identified displacement and velocity per mass (PNG)."""
from __future__ import annotations

from pathlib import Path
from types import ModuleType
from typing import Mapping

import numpy as np

from suspid.models.base import FloatArray, SuspensionModel
from suspid.simulate import outputs, road_matrix, simulate_states


def _plt() -> ModuleType:
    # matplotlib.pyplot is slow to import: loaded on first use
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    return plt


def plot_channels(model: SuspensionModel, t: FloatArray, series: Mapping[str, Mapping[str, FloatArray]],
                  path: str | Path, title: str = "") -> None:
    """One row per coordinate: displacement (left) and velocity (right); one line per series."""
    plt = _plt()
    nq = len(model.coords)
    fig, axes = plt.subplots(nq, 2, figsize=(10, 2.4 * nq + 0.6), squeeze=False, sharex=True)
    styles = ["-", "--", ":", "-."]
    for i, c in enumerate(model.coords):
        for j, ch in enumerate((c, f"{c}_dot")):
            ax = axes[i][j]
            for s, (label, data) in enumerate(series.items()):
                if ch in data:
                    ax.plot(t, data[ch], styles[s % 4], lw=1.2, label=label)
            unit = ("rad" if c == "delta" else "m") + ("/s" if j else "")
            ax.set_ylabel(f"{ch} ({unit})")
            ax.grid(alpha=0.3)
        axes[i][0].legend(loc="best", fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("t (s)")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_comparison(model: SuspensionModel, meas, result, path: str | Path) -> None:
    """Measured channels against the identified model's simulation (seed Figs. 17-28)."""
    U = road_matrix(model, meas.t, meas.road)
    X = simulate_states(model, result.params, meas.t, U, np.asarray(result.x0))
    sim = outputs(model, result.params, X, U)
    plot_channels(model, meas.t, {"measured": meas.measured, "identified": sim}, path,
                  title=f"{model.name}: measured vs identified ({'success' if result.success else 'check warnings'})")
