"""Measured and computed readings along every instrument with +-2 sigma bands and whitened residuals."""
from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.transforms import blended_transform_factory

from ..simulation import is_instrument_term
from .common import BEFORE, direction_words, new_figure


def instruments_figure(res, exploration=None, before: np.ndarray | None = None, before_label: str = "before",
                       title: str | None = None) -> Figure:
    """Measured and computed readings along every instrument, +-2 sigma from diag C_x, and the
    model along each line where the exploration has it; `before` adds another model's readings
    (e.g. the baseline of a diagnosis) as a dashed red line."""
    f = res.fit
    blocks = res.data.blocks
    profiles = exploration.profiles if exploration is not None else {}
    nb = len(blocks)
    ncols = min(nb, 3)
    nrows = int(np.ceil(nb / ncols))
    fig = new_figure(4.9 * ncols + 0.6, 5.2 * nrows)
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False)).ravel()
    measured, computed = res.data.measured, f.x
    sigma = np.sqrt(np.clip(np.diag(res.data.covariance), 0, None))
    rw = res.standardised  # whitened with the case's C_x
    identified = {n for n in res.parameters.names if is_instrument_term(n)}  # the line lacks them
    mm = 1e3
    row0 = 0
    for ax, block in zip(axes, blocks):
        rows = np.arange(row0, row0 + len(block.labels))
        row0 += len(block.labels)
        xm, xc, sg, r_ = measured[rows] * mm, computed[rows] * mm, sigma[rows] * mm, rw[rows]
        xb = before[rows] * mm if before is not None else None
        chi2_block = float(r_ @ r_)
        linewise = block.integration is not None
        if linewise:
            w0 = block.weights[0, 0]  # the measured direction (the same at every station)
            what = {"inclinometer": "horizontal displacement u_x", "deflectometer": "displacement normal to the line"
                    }.get(block.kind, "displacement along the line")
            what += f" ({direction_words(w0)})"
            if block.relative:
                what = what.replace(" (", " relative to the reference end\n(", 1)
        if linewise:
            st = block.stations
            d = st[-1] - st[0] if len(st) > 1 else np.array([0.0, -1.0])
            vertical = abs(d[1]) >= abs(d[0])
            coord = -st[:, 1] if vertical else st[:, 0]
            dense = None
            prof = profiles.get(block.name)
            if prof is not None and prof.line is not None and not any(n.endswith(f"[{block.name}]") for n in identified):
                dense = (prof.line_reading * mm,
                         -prof.line[:, 1] if vertical else prof.line[:, 0])
            # draw (value, coordinate) pairs: depth downwards for vertical lines, x across otherwise
            pair = (lambda v, c: (v, c)) if vertical else (lambda v, c: (c, v))
            (ax.fill_betweenx if vertical else ax.fill_between)(coord, xm - 2 * sg, xm + 2 * sg, color="0.55",
                                                                alpha=0.25, lw=0, label="measured ± 2σ (case C_x)")
            if dense is not None:
                ax.plot(*pair(dense[0], dense[1]), color="#1f77b4", lw=1.2, alpha=0.7, label="model along the line")
            ax.plot(*pair(xc, coord), ls="none", marker="o", ms=6, mfc="white", mec="#1f77b4", mew=1.6,
                    label="computed at stations")
            if xb is not None:
                ax.plot(*pair(xb, coord), ls="--", marker="s", ms=3.5, lw=1.2, color=BEFORE, label=before_label)
            ax.plot(*pair(xm, coord), ls="none", marker="x", ms=7, mew=1.8, color="k", label="measured")
            (ax.axvline if vertical else ax.axhline)(0, color="0.7", lw=0.7, zorder=0)
            if vertical:
                ax.invert_yaxis()
                ax.set_ylabel("depth below the surface [m]")
                ax.set_xlabel(f"{what} [mm]")
                tr = blended_transform_factory(ax.transAxes, ax.transData)
                for c_, rv in zip(coord, r_):
                    ax.text(1.01, c_, f"{rv:+.2f}", transform=tr, fontsize=7.5, va="center", ha="left",
                            color="#b22222" if abs(rv) > 2 else "0.25")
                ax.text(1.01, 1.0, "r′", transform=ax.transAxes, fontsize=8, va="bottom", ha="left",
                        fontweight="bold")
            else:
                ax.set_xlabel("horizontal distance from the symmetry axis x [m]")
                ax.set_ylabel(f"{what} [mm]")
                tr = blended_transform_factory(ax.transData, ax.transAxes)
                for c_, rv in zip(coord, r_):  # residuals along the top, inside the frame
                    ax.text(c_, 0.985, f"{rv:+.2f}", transform=tr, fontsize=7, va="top", ha="center",
                            rotation=90 if len(coord) > 8 else 0, color="#b22222" if abs(rv) > 2 else "0.25",
                            bbox=dict(boxstyle="round,pad=0.1", fc="white", ec="none", alpha=0.7))
                lo_, hi_ = ax.get_ylim()
                ax.set_ylim(lo_, hi_ + 0.12 * (hi_ - lo_))  # room for the residuals
        else:
            k = np.arange(1, len(rows) + 1)
            ax.errorbar(k, xm, yerr=2 * sg, ls="none", marker="x", ms=7, mew=1.8, color="k", capsize=4,
                        elinewidth=1.0, label="measured ± 2σ (case C_x)")
            ax.plot(k, xc, ls="none", marker="o", ms=6, mfc="white", mec="#1f77b4", mew=1.6, label="computed")
            if xb is not None:
                ax.plot(k, xb, ls="none", marker="s", ms=5, color=BEFORE, label=before_label)
            ax.set_xticks(k)
            if block.kind == "points":
                ax.set_xticklabels([f"{lab.component} at ({lab.x:g}, {lab.y:g})" for lab in block.labels],
                                   rotation=35, ha="right", rotation_mode="anchor")
                ax.set_xlabel("reading: component at point (x, y) [m]")
                ax.set_ylabel("displacement [mm]\n(u_x + away from the axis, u_y + up)")
            else:
                ax.set_xticklabels([f"chord {lab.station}" for lab in block.labels])
                ax.set_xlabel("chord")
                ax.set_ylabel("change of chord length (+ lengthening) [mm]")
            ax.set_xlim(0.4, len(rows) + 0.6)
            for k_, y_, rv in zip(k, xm, r_):
                ax.annotate(f"r′={rv:+.2f}", (k_, y_), xytext=(6, 0), textcoords="offset points", fontsize=7.5,
                            va="center", color="#b22222" if abs(rv) > 2 else "0.25")
        ax.set_title(f"{block.name} ({block.kind}, {len(rows)} readings)", fontsize=10)
        ax.text(0.03, 0.03, f"Σ r′² = {chi2_block:.3g}\nmax |r′| = {np.max(np.abs(r_)):.3g}",
                transform=ax.transAxes, fontsize=8, va="bottom", ha="left",
                bbox=dict(boxstyle="round,pad=0.3", fc="white", ec="0.7", alpha=0.9))
        ax.grid(True, color="0.92", lw=0.6)
        ax.set_axisbelow(True)
    for ax in axes[nb:]:
        ax.set_visible(False)
    handles = [Patch(color="0.55", alpha=0.25, label="measured ± 2σ (σ from diag C_x of the case)"),
               Line2D([], [], color="#1f77b4", lw=1.2, alpha=0.7, label="model along the line (at p̂)"),
               Line2D([], [], ls="none", marker="o", ms=6, mfc="white", mec="#1f77b4", mew=1.6,
                      label="computed at the stations"),
               Line2D([], [], ls="none", marker="x", ms=7, mew=1.8, color="k", label="measured"),
               Line2D([], [], ls="none", marker="$r′$", ms=9, color="0.25",
                      label="whitened residual r′ = L⁻¹(x* − x(p̂)) (red if |r′| > 2)")]
    if before is not None:
        handles.append(Line2D([], [], ls="--", marker="s", ms=3.5, lw=1.2, color=BEFORE, label=before_label))
    fig.legend(handles=handles, loc="outside lower center", ncols=3, fontsize=8.5, frameon=False)
    fig.suptitle(title or f"Measured and computed readings at the estimate (fit: {res.weighting} "
                          f"weighting; σ and whitened residuals r′ from the case's C_x)", fontsize=10.5)
    return fig

