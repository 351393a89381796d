"""Information density (paper Figs. 5 and 8): rows of Q = A'(A'^t A')^-1 A'^t for the readings of
highest leverage, and Q itself."""
from __future__ import annotations

import numpy as np
from matplotlib import colormaps
from matplotlib.colors import TwoSlopeNorm
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from geoback.reports.plots.common import multi_component, new_figure, short_label


def information_density_figure(res, top: int = 3) -> Figure:
    """Rows of Q for the readings of highest leverage (paper Figs. 5, 8) and Q as a heat map."""
    rel = res.reliability
    labels = res.data.labels
    Q = rel.information_density
    m = len(labels)
    multi = multi_component(labels)
    short = [short_label(labels, i, multi) for i in range(m)]
    if len({lab.stage for lab in labels}) > 1:  # readings of several construction stages
        short = [f"{t}@{lab.stage}" for t, lab in zip(short, labels)]
    instruments = list(dict.fromkeys(lab.instrument for lab in labels))
    colours = colormaps["tab10"]
    inst_colour = {name: colours(k % 10) for k, name in enumerate(instruments)}
    picks = list(np.argsort(-rel.leverage, kind="stable")[:min(top, m)])
    fig = new_figure(12.5, 2.0 + 1.9 * len(picks))
    gs = fig.add_gridspec(len(picks), 2, width_ratios=[1.45, 1.0])
    idx = np.arange(1, m + 1)
    show_ticks = m <= 40
    vmax = max(np.nanmax(np.abs(Q)), 1e-12)
    for r, i in enumerate(picks):
        ax = fig.add_subplot(gs[r, 0])
        cols = [inst_colour[lab.instrument] for lab in labels]
        bars = ax.bar(idx, Q[i], color=cols, edgecolor="none", width=0.75)
        bars[i].set_edgecolor("k")
        bars[i].set_linewidth(1.5)
        ax.axhline(0, color="0.3", lw=0.7)
        ax.set_ylim(min(-0.05 * vmax, 1.15 * Q[i].min()), 1.18 * max(Q[i].max(), 0.05 * vmax))
        ax.set_xlim(0.3, m + 0.7)
        ax.set_ylabel(f"Q[{short[i]}, j] [-]")
        ax.set_title(f"Information density: row of reading {short[i]} "
                     f"({labels[i].kind}, leverage Q_ii = {rel.leverage[i]:.3f})", loc="left", fontsize=9.5)
        if show_ticks:
            ax.set_xticks(idx)
            ax.set_xticklabels(short if r == len(picks) - 1 else [""] * m, rotation=90 if m > 12 else 45,
                               ha="center" if m > 12 else "right", rotation_mode="anchor" if m <= 12 else "default")
        ax.set_xlabel("reading j (instrument:station)" if r == len(picks) - 1 else "reading j")
        ax.grid(True, axis="y", color="0.9", lw=0.6)
        ax.set_axisbelow(True)
        if r == 0:
            ax.legend(handles=[Patch(color=inst_colour[nm], label=nm) for nm in instruments], ncols=len(instruments),
                      loc="upper left", fontsize=8, framealpha=0.9)
    axh = fig.add_subplot(gs[:, 1])
    im = axh.imshow(Q, cmap="RdBu_r", norm=TwoSlopeNorm(0.0, -vmax, vmax), interpolation="nearest",
                    extent=(0.5, m + 0.5, m + 0.5, 0.5), aspect="auto")
    if show_ticks:
        axh.set_xticks(idx)
        axh.set_yticks(idx)
        axh.set_xticklabels(short, rotation=90, fontsize=7 if m > 20 else 8)
        axh.set_yticklabels(short, fontsize=7 if m > 20 else 8)
    # instrument separators
    bounds = np.flatnonzero([labels[k].instrument != labels[k - 1].instrument for k in range(1, m)]) + 1.5
    for bnd in bounds:
        axh.axhline(bnd, color="k", lw=0.8)
        axh.axvline(bnd, color="k", lw=0.8)
    axh.set_xlabel("reading j")
    axh.set_ylabel("reading i")
    axh.set_title(f"Information density matrix Q (trace = {np.trace(Q):.2f})", fontsize=10)
    if res.weighting == "full" and any(b.integration is not None for b in res.data.blocks):
        fig.suptitle("Q relates the whitened readings L⁻¹x (full weighting): for linewise instruments "
                     "the i-th whitened reading is essentially the i-th primary (incremental) reading",
                     fontsize=9.5, color="0.25")
    cb = fig.colorbar(im, ax=axh, shrink=0.95, pad=0.02)
    cb.set_label("Q_ij [-]")
    return fig

