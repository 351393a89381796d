"""Measured against computed readings of every instrument in one picture: x = measured, y = computed
at the estimate, ±2σ of each reading (diag C_x), the 1:1 line; one colour per instrument and one
marker per construction stage, in mm (load cells' forces in kN, in a panel of their own)."""
from __future__ import annotations

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from geoback.reports.plots.common import new_figure, plain

MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
MM = 1e3


FORCE_KINDS = ("load_cell",)  # readings of a force [kN], drawn in their own panel


def measured_vs_predicted_figure(res, exploration=None) -> Figure:
    """Every reading as a point (measured, computed) with horizontal ±2σ bars and the 1:1 line; the
    displacement readings in mm, load cells' forces (if any) in kN in a panel of their own."""
    data = res.data
    sigma_all = np.sqrt(np.clip(np.diag(data.covariance), 0, None))
    r = res.standardised
    instruments = list(dict.fromkeys(b.name for b in data.blocks))
    stages = list(dict.fromkeys(b.stage for b in data.blocks))
    colours = colormaps["tab10"]
    kinds = [(False, MM, "mm", "reading"), (True, 1.0, "kN", "force in a prop or anchor")]
    kinds = [k for k in kinds if any((b.kind in FORCE_KINDS) == k[0] for b in data.blocks)]
    fig = new_figure(6.8 * len(kinds), 6.4)
    axes = np.atleast_1d(fig.subplots(1, len(kinds)))
    for ax, (force, scale, unit, word) in zip(axes, kinds):
        sel = [(b, rows) for b, rows in data.block_rows() if (b.kind in FORCE_KINDS) == force]
        idx = np.concatenate([np.arange(rows.start, rows.stop) for _, rows in sel])
        measured, computed, sigma = data.measured * scale, res.fit.x * scale, sigma_all * scale
        for block, rows in sel:
            c = colours(instruments.index(block.name) % 10)
            mk = MARKERS[stages.index(block.stage) % len(MARKERS)] if len(stages) > 1 else "o"
            ax.errorbar(measured[rows], computed[rows], xerr=2 * sigma[rows], ls="none", marker=mk, ms=5.5, mfc=c,
                        mec="white", mew=0.6, color=c, ecolor=c, elinewidth=0.9, capsize=2.5, alpha=0.9, zorder=3)
        lo = float(min((measured[idx] - 2 * sigma[idx]).min(), computed[idx].min(), 0.0))
        hi = float(max((measured[idx] + 2 * sigma[idx]).max(), computed[idx].max(), 0.0))
        pad = 0.05 * max(hi - lo, 1e-9)
        lo, hi = lo - pad, hi + pad
        ax.plot([lo, hi], [lo, hi], color="0.3", lw=1.0, ls="--", zorder=1)
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)
        ax.set_aspect("equal")
        ax.grid(True, color="0.92", lw=0.6)
        ax.set_axisbelow(True)
        ax.set_xlabel(f"measured {word} [{unit}]")
        ax.set_ylabel(f"computed {word} at the estimate [{unit}]")
        if len(kinds) > 1:
            ax.set_title("load cells" if force else "displacement readings", fontsize=10)
    ax = axes[0]
    handles = []
    for name in instruments:
        blocks = [b for b in data.blocks if b.name == name]
        rows = np.concatenate([np.arange(sl.start, sl.stop) for b, sl in data.block_rows() if b.name == name])
        chi2 = float(r[rows] @ r[rows])
        handles.append(Line2D([], [], ls="none", marker="o", ms=6, mfc=colours(instruments.index(name) % 10),
                              mec="white", label=f"{name} ({blocks[0].kind.replace('_', ' ')}, {len(rows)} readings, "
                                                 f"Σ r′² = {plain(chi2)})"))
    if len(stages) > 1:
        handles += [Line2D([], [], ls="none", marker=MARKERS[k % len(MARKERS)], ms=6, color="0.4",
                           label=f"after stage '{stg}'") for k, stg in enumerate(stages)]
    handles += [Line2D([], [], color="0.3", lw=1.0, ls="--", label="1:1 (computed = measured)"),
                Line2D([], [], color="0.4", lw=0.9, marker="|", ms=8, label="measured ± 2σ (diag C_x of the case)")]
    if len(axes) > 1:
        fig.legend(handles=handles, loc="outside lower center", ncols=3, fontsize=8, frameon=False)
    else:
        ax.legend(handles=handles, loc="upper left", fontsize=8, framealpha=0.92)
    rel = res.reliability
    fig.suptitle(f"{res.name}: measured against computed readings at the estimate\n"
                 f"all {data.m} readings of {len(instruments)} instrument(s); χ² = {rel.chi2:.4g} on {rel.dof:.4g} "
                 f"degrees of freedom (p = {rel.p_value:.2g})", fontsize=10.5)
    return fig
