"""Evidence figure of ``suspid diagnose --plot`` (PNG, Agg backend)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from estimator.diagnose.core import DiagnoseResult
from estimator.diagnose.residuals import autocorr, residual_force
from suspid.io.csvio import Measurement
from suspid.models import get_model
from suspid.errors import UsageError
from suspid.effects import PhysicalEffect, Site
from suspid.plots import _plt


def plot_evidence(res: DiagnoseResult, meas: Measurement, path: str | Path) -> None:
    """Write the evidence figure for a :func:`~estimator.diagnose.diagnose` result.

    Left: every channel's residual before and after. Right: the autocorrelation of the most
    structured residual, the residual force against the effect's site, and each candidate's share.
    """
    plt = _plt()
    model = get_model(res.model)
    t = meas.t
    chans = list(res.baseline.residual)
    nrow = max(len(chans), 3)
    fig = plt.figure(figsize=(12, 2.2 * nrow + 0.8))
    gs = fig.add_gridspec(nrow, 2)
    for i, c in enumerate(chans):
        ax = fig.add_subplot(gs[i, 0])
        ax.plot(t, res.baseline.residual[c], lw=0.9, label="baseline")
        ax.plot(t, res.augmented.residual[c], lw=0.9, label="augmented")
        ax.set_ylabel(f"e {c}")
        ax.grid(alpha=0.3)
        if i == 0:
            ax.legend(fontsize=8, loc="best")
            eff = res.effect.name if res.effect is not None else "none"
            ax.set_title(f"residual, measured - model (effect: {eff})", fontsize=9)
    ax.set_xlabel("t (s)")
    # autocorrelation
    worst = max(chans, key=lambda c: res.stats[c].ljung_box_q)
    lags = min(60, t.size // 4)
    ax = fig.add_subplot(gs[0, 1])
    k = np.arange(lags + 1)
    ax.stem(k, autocorr(res.baseline.residual[worst], lags), linefmt="C0-", markerfmt="C0.",
            basefmt=" ", label="baseline")
    ax.plot(k, autocorr(res.augmented.residual[worst], lags), "C1.-", lw=0.8, label="augmented")
    band = 2.576 / np.sqrt(t.size)
    ax.axhspan(-band, band, color="0.85")
    ax.set_title(f"autocorrelation of e {worst} (Ljung-Box p = {res.stats[worst].ljung_box_p:.2g})",
                 fontsize=9)
    ax.set_xlabel("lag (samples)")
    ax.legend(fontsize=8)
    # residual force against the strut coordinate
    ax = fig.add_subplot(gs[1, 1])
    sites: list[Site] = []
    use_rate = True
    if res.motion is not None:
        R = residual_force(model, res.baseline.params, res.motion)
        try:
            sites = model.strut_sites(res.baseline.params) or model.tyre_sites(res.baseline.params)
        except UsageError:
            sites = []
        if isinstance(res.effect, PhysicalEffect) and res.effect.site_kind == "strut":
            sites = res.effect.sites(model, res.baseline.params)   # e.g. the rear strut alone
        use_rate = not (isinstance(res.effect, PhysicalEffect) and res.effect.plot_against == "deflection")
    if res.motion is not None and sites:
        site = sites[0]
        s, sd = site.coordinate(np.column_stack([res.motion.q, res.motion.qd]),
                                np.column_stack([res.motion.r, res.motion.rd]))
        x = sd if use_rate else s
        ax.plot(x, R[:, 0], ".", ms=2, color="0.6", label="samples")
        edges = np.quantile(x, np.linspace(0, 1, 26))
        idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, 24)
        cnt = np.bincount(idx, minlength=25)
        keep = cnt > 0
        xm = np.bincount(idx, x, 25)[keep] / cnt[keep]
        rm = np.bincount(idx, R[:, 0], 25)[keep] / cnt[keep]
        ax.plot(xm, rm, "C3o-", ms=3, lw=1.2, label="binned mean")
        ax.legend(fontsize=7)
        ax.set_xlabel(f"{site.name} {'rate (m/s)' if use_rate else 'deflection (m)'}")
        ax.set_ylabel(f"residual force, {model.coords[0]} eq. (N)")
        ax.set_title("residual force from measured motion (baseline parameters)", fontsize=9)
        ax.grid(alpha=0.3)
    # candidate scores
    ax = fig.add_subplot(gs[2, 1])
    names = [s.name for s in res.screens]
    scr = [s.explained for s in res.screens]
    refit = {v.name: v.explained for v in res.verdicts}
    y = np.arange(len(names))
    ax.barh(y - 0.2, scr, height=0.4, label="screen (share explained)")
    ax.barh(y + 0.2, [max(min(refit.get(n, 0.0), 1.2), 0.0) for n in names], height=0.4,
            label="refit (share of structured residual)")
    ax.set_yticks(y, names, fontsize=8)
    ax.axvline(res.evidence["thresholds"]["explained"], color="k", lw=0.8, ls="--")
    ax.set_xlim(0, 1.2)
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title("candidate effects", fontsize=9)
    fig.suptitle(res.evidence.get("verdict", ""), fontsize=8)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.3 / fig.get_figheight()))   # room for the verdict
    fig.savefig(path, dpi=100)
    plt.close(fig)
