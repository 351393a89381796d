"""Measured and computed readings along every instrument with +-2 sigma bands and whitened residuals."""
from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.transforms import blended_transform_factory

from geoback.physics.simulation import is_instrument_term
from geoback.reports.plots.common import BEFORE, direction_words, new_figure


STAGE_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#17becf", "#e377c2", "#7f7f7f")


def _groups(blocks):
    """Blocks of the same instrument (read at several construction stages) with their rows."""
    out: dict[str, list] = {}
    row0 = 0
    for block in blocks:
        out.setdefault(block.name, []).append((block, np.arange(row0, row0 + len(block.labels))))
        row0 += len(block.labels)
    return list(out.values())


def instruments_figure(res, exploration=None, before: np.ndarray | None = None, before_label: str = "before",
                       title: str | None = None) -> Figure:
    """Measured and computed readings along every instrument, +-2 sigma from diag C_x, and the
    model along each line where the exploration has it; one panel per instrument, with one colour
    per construction stage when it was read at several; `before` adds another model's readings
    (e.g. the baseline of a diagnosis) as a dashed red line."""
    f = res.fit
    groups = _groups(res.data.blocks)
    stages = list(dict.fromkeys(b.stage for b in res.data.blocks))
    staged = len(stages) > 1
    profiles = exploration.profiles if exploration is not None else {}
    nb = len(groups)
    ncols = min(nb, 3)
    nrows = int(np.ceil(nb / ncols))
    fig = new_figure(4.9 * ncols + 0.6 + 0.5 * staged, 5.2 * nrows)
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False)).ravel()
    measured, computed = res.data.measured, f.x
    sigma = np.sqrt(np.clip(np.diag(res.data.covariance), 0, None))
    rw = res.standardised  # whitened with the case's C_x
    identified = {n for n in res.parameters.names if is_instrument_term(n)}  # the line lacks them
    mm = 1e3
    for ax, group in zip(axes, groups):
        block = group[0][0]
        linewise = block.integration is not None
        prof = profiles.get(block.name)
        chi2_lines = []
        if linewise:
            w0 = block.measured  # the measured direction (the same at every station)
            what = block.measures + (" u_x" if block.kind == "inclinometer" else "")
            what += f" ({direction_words(w0)})"
            if block.relative:
                what = what.replace(" (", " relative to the reference end\n(", 1)
            st = block.stations
            vertical = abs(block.along[1]) >= abs(block.along[0])
            coord = -st[:, 1] if vertical else st[:, 0]
            pair = (lambda v, c: (v, c)) if vertical else (lambda v, c: (c, v))
        keys = sorted({(lab.station, lab.component) for blk, _ in group for lab in blk.labels})
        for k, (blk, rows) in enumerate(group):
            if linewise:  # the stations this survey read (one may have been marked missing)
                coord = -blk.stations[:, 1] if vertical else blk.stations[:, 0]
            colour = STAGE_COLOURS[stages.index(blk.stage) % len(STAGE_COLOURS)] if staged else "#1f77b4"
            mark = colour if staged else "k"
            band = colour if staged else "0.55"
            xm, xc, sg, r_ = measured[rows] * mm, computed[rows] * mm, sigma[rows] * mm, rw[rows]
            xb = before[rows] * mm if before is not None else None
            chi2_lines.append((blk.stage, float(r_ @ r_), float(np.max(np.abs(r_)))))
            if linewise:
                dense = None
                if prof is not None and prof.line is not None and \
                        not any(n.endswith(f"[{block.name}]") for n in identified):
                    line_reading = prof.stage_readings.get(blk.stage, prof.line_reading) if staged else prof.line_reading
                    dense = (line_reading * mm, -prof.line[:, 1] if vertical else prof.line[:, 0])
                # draw (value, coordinate) pairs: depth downwards for vertical lines, x across otherwise
                (ax.fill_betweenx if vertical else ax.fill_between)(coord, xm - 2 * sg, xm + 2 * sg, color=band,
                                                                    alpha=0.18 if staged else 0.25, lw=0)
                if dense is not None:
                    ax.plot(*pair(dense[0], dense[1]), color=colour, lw=1.2, alpha=0.7)
                ax.plot(*pair(xc, coord), ls="none", marker="o", ms=6, mfc="white", mec=colour, mew=1.6)
                if xb is not None:
                    ax.plot(*pair(xb, coord), ls="--", marker="s", ms=3.5, lw=1.2, color=BEFORE)
                ax.plot(*pair(xm, coord), ls="none", marker="x", ms=7, mew=1.8, color=mark)
                rcol = (lambda rv: "#b22222" if abs(rv) > 2 else (colour if staged else "0.25"))
                if vertical:
                    tr = blended_transform_factory(ax.transAxes, ax.transData)
                    for c_, rv in zip(coord, r_):
                        ax.text(1.01 + 0.1 * k, c_, f"{rv:+.2f}", transform=tr, fontsize=7.5, va="center",
                                ha="left", color=rcol(rv))
                    if k == 0:
                        ax.text(1.01, 1.0, "r′", transform=ax.transAxes, fontsize=8, va="bottom", ha="left",
                                fontweight="bold")
                else:
                    tr = blended_transform_factory(ax.transData, ax.transAxes)
                    for c_, rv in zip(coord, r_):  # residuals along the top, inside the frame
                        ax.text(c_, 0.985 - 0.07 * k, f"{rv:+.2f}", transform=tr, fontsize=7, va="top",
                                ha="center", rotation=90 if len(coord) > 8 else 0, color=rcol(rv),
                                bbox=dict(boxstyle="round,pad=0.1", fc="white", ec="none", alpha=0.7))
            else:
                shift = 0.16 * (k - (len(group) - 1) / 2)
                kk = np.array([keys.index((lab.station, lab.component)) + 1 for lab in blk.labels]) + shift
                ax.errorbar(kk, xm, yerr=2 * sg, ls="none", marker="x", ms=7, mew=1.8, color=mark, capsize=4,
                            elinewidth=1.0)
                ax.plot(kk, xc, ls="none", marker="o", ms=6, mfc="white", mec=colour, mew=1.6)
                if xb is not None:
                    ax.plot(kk, xb, ls="none", marker="s", ms=5, color=BEFORE)
                for k_, y_, rv in zip(kk, xm, r_):
                    ax.annotate(f"r′={rv:+.2f}", (k_, y_), xytext=(6, 0), textcoords="offset points", fontsize=7.5,
                                va="center", color="#b22222" if abs(rv) > 2 else (colour if staged else "0.25"))
        m = len(keys)
        if linewise:
            (ax.axvline if vertical else ax.axhline)(0, color="0.7", lw=0.7, zorder=0)
            if vertical:
                ax.invert_yaxis()
                ax.set_ylabel("depth below the surface [m]")
                ax.set_xlabel(f"{what} [mm]")
            else:
                ax.set_xlabel("horizontal distance from the symmetry axis x [m]")
                ax.set_ylabel(f"{what} [mm]")
                lo_, hi_ = ax.get_ylim()
                ax.set_ylim(lo_, hi_ + (0.12 + 0.07 * (len(group) - 1)) * (hi_ - lo_))  # room for the residuals
        else:
            k = np.arange(1, m + 1)
            ax.set_xticks(k)
            if block.kind == "points":
                where = {(lab.station, lab.component): (lab.x, lab.y) for blk, _ in group for lab in blk.labels}
                ax.set_xticklabels([f"{c} at ({where[(st, c)][0]:g}, {where[(st, c)][1]:g})" for st, c in keys],
                                   rotation=35, ha="right", rotation_mode="anchor")
                ax.set_xlabel("reading: component at point (x, y) [m]")
                ax.set_ylabel("displacement [mm]\n(u_x + away from the axis, u_y + up)")
            else:
                ax.set_xticklabels([f"chord {st}" for st, _ in keys])
                ax.set_xlabel("chord")
                ax.set_ylabel("change of chord length (+ lengthening) [mm]")
            ax.set_xlim(0.4, m + 0.6)
        n_read = sum(len(rows) for _, rows in group)
        ax.set_title(f"{block.name} ({block.kind}, {n_read} readings"
                     + (f" at {len(group)} stages)" if len(group) > 1 else ")"), fontsize=10)
        if len(chi2_lines) == 1:
            box = f"Σ r′² = {chi2_lines[0][1]:.3g}\nmax |r′| = {chi2_lines[0][2]:.3g}"
        else:
            box = "\n".join(f"{stg}: Σ r′² = {c:.3g}, max |r′| = {mx:.3g}" for stg, c, mx in chi2_lines)
        ax.text(0.03, 0.03, box, transform=ax.transAxes, fontsize=8, va="bottom", ha="left",
                bbox=dict(boxstyle="round,pad=0.3", fc="white", ec="0.7", alpha=0.9))
        ax.grid(True, color="0.92", lw=0.6)
        ax.set_axisbelow(True)
    for ax in axes[nb:]:
        ax.set_visible(False)
    if staged:
        handles = [Patch(color=STAGE_COLOURS[i % len(STAGE_COLOURS)], alpha=0.5,
                         label=f"after stage '{stg}' (band: measured ± 2σ, line: model, o computed, x measured)")
                   for i, stg in enumerate(stages)]
        handles.append(Line2D([], [], ls="none", marker="$r′$", ms=9, color="0.25",
                              label="whitened residuals r′ = L⁻¹(x* − x(p̂)), one column per stage (red if |r′| > 2)"))
    else:
        handles = [Patch(color="0.55", alpha=0.25, label="measured ± 2σ (σ from diag C_x of the case)"),
                   Line2D([], [], color="#1f77b4", lw=1.2, alpha=0.7, label="model along the line (at p̂)"),
                   Line2D([], [], ls="none", marker="o", ms=6, mfc="white", mec="#1f77b4", mew=1.6,
                          label="computed at the stations"),
                   Line2D([], [], ls="none", marker="x", ms=7, mew=1.8, color="k", label="measured"),
                   Line2D([], [], ls="none", marker="$r′$", ms=9, color="0.25",
                          label="whitened residual r′ = L⁻¹(x* − x(p̂)) (red if |r′| > 2)")]
    if before is not None:
        handles.append(Line2D([], [], ls="--", marker="s", ms=3.5, lw=1.2, color=BEFORE, label=before_label))
    fig.legend(handles=handles, loc="outside lower center", ncols=2 if staged else 3, fontsize=8.5, frameon=False)
    fig.suptitle(title or f"Measured and computed readings at the estimate (fit: {res.weighting} "
                          f"weighting; σ and whitened residuals r′ from the case's C_x)"
                          + (f"\nreadings accumulated up to each construction stage: {', '.join(stages)}"
                             if staged else ""), fontsize=10.5)
    return fig
