"""Measured and computed readings along every instrument with +-2 sigma bands and whitened residuals;
the same figure without measured values for a forward run (`geoback simulate --plots`).

Every instrument is drawn against where it is: a linewise instrument against depth (a vertical
line) or x (any other), settlement points against their x (a row of points, e.g. the surface
trough) or their depth (a column of points), never against a reading number."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.transforms import blended_transform_factory

from geoback.physics.simulation import is_instrument_term
from geoback.reports.plots.common import BEFORE, direction_words, new_figure, plain


STAGE_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#17becf", "#e377c2", "#7f7f7f")
BOUNDARY = "#8c564b"  # an identified layer boundary
LABELS_MAX = 25  # residual labels per column of an instrument; beyond, every k-th station (and all beyond 2)
MM = 1e3
COMPONENT_WORDS = {"ux": "horizontal displacement u_x (+ away from the axis)",
                   "uy": "vertical displacement u_y (+ up)"}
COMPONENT_MARK = {"uy": dict(marker="x", ls="-"), "ux": dict(marker="+", ls=":")}


@dataclass(frozen=True)
class Boundary:
    """A horizontal line to draw at a depth on the panels with a depth axis (an identified layer
    boundary) with its 95 % interval as a band."""

    depth: float
    low: float = float("nan")
    high: float = float("nan")
    label: str = "boundary"


@dataclass
class _Readings:
    """What the panels draw: the readings of `blocks` (in row order), computed and, for a fit, measured."""

    blocks: list
    computed: np.ndarray
    sigma: np.ndarray
    measured: np.ndarray | None = None
    residual: np.ndarray | None = None  # whitened, with the case's C_x
    no_line: set = field(default_factory=set)  # instruments whose model line would lack identified terms


def _groups(blocks):
    """Blocks of the same instrument (read at several construction stages) with their rows."""
    out: dict[str, list] = {}
    row0 = 0
    for block in blocks:
        out.setdefault(block.name, []).append((block, np.arange(row0, row0 + len(block.labels))))
        row0 += len(block.labels)
    return list(out.values())


def grid_shape(n: int) -> tuple[int, int]:
    """Rows and columns for n panels: at most 3 columns (4 beyond six panels), rows balanced so that
    at most one panel of the last row stays empty where that can be had."""
    most = 4 if n > 6 else 3
    rows = int(np.ceil(n / most))
    return rows, int(np.ceil(n / rows))


def labelled(residual: np.ndarray, limit: int = LABELS_MAX) -> np.ndarray:
    """Indices of the readings whose residual is written beside them: all up to `limit`; beyond, every
    k-th station (k = ceil(n / limit)) and every one beyond ±2, without two closer than k / 2."""
    n = len(residual)
    if n <= limit:
        return np.arange(n)
    step = int(np.ceil(n / limit))
    flagged = np.flatnonzero(np.abs(residual) > 2)
    regular = [k for k in range(0, n, step) if not len(flagged) or np.min(np.abs(flagged - k)) >= step / 2]
    return np.unique(np.concatenate([flagged, np.array(regular, int)]))


def points_layout(block) -> tuple[bool, np.ndarray, str]:
    """(vertical, position of each reading, axis label): a column of points (x the same, depth
    varying) is drawn against depth, anything else against x."""
    pts = block.points
    vertical = np.ptp(pts[:, 0]) < 1e-9 * max(np.ptp(pts[:, 1]), 1.0) and np.ptp(pts[:, 1]) > 0
    if vertical:
        return True, np.array([-lab.y for lab in block.labels]), "depth below the surface [m]"
    return False, np.array([lab.x for lab in block.labels]), X_WORDS


def _residual_texts(ax, coord, r_, k, colour_of, side_column: bool) -> None:
    show = labelled(r_)
    if side_column:  # a column beside the panel, one per stage (vertical lines)
        tr = blended_transform_factory(ax.transAxes, ax.transData)
        for q in show:
            ax.text(1.01 + 0.1 * k, coord[q], f"{r_[q]:+.2f}", transform=tr, fontsize=7.5, va="center", ha="left",
                    color=colour_of(r_[q]))
        if k == 0:
            ax.text(1.01, 1.0, "r′", transform=ax.transAxes, fontsize=8, va="bottom", ha="left", fontweight="bold")
    else:  # along the top, inside the frame
        tr = blended_transform_factory(ax.transData, ax.transAxes)
        rotate = 90 if len(show) > 8 else 0
        for q in show:
            ax.text(coord[q], 0.985 - (0.1 if rotate else 0.07) * k, f"{r_[q]:+.2f}", transform=tr, fontsize=7,
                    va="top", ha="center", rotation=rotate, color=colour_of(r_[q]),
                    bbox=dict(boxstyle="round,pad=0.1", fc="white", ec="none", alpha=0.7))


def _linewise(ax, block, group, data, prof, staged, stages, before) -> bool:
    w0 = block.measured  # the measured direction (the same at every station)
    what = block.measures + (" u_x" if block.kind == "inclinometer" else "")
    what += f" ({direction_words(w0)})"
    if block.relative:
        what = what.replace(" (", " relative to the reference end\n(", 1)
    st = block.stations
    vertical = abs(block.along[1]) >= abs(block.along[0])
    coord = -st[:, 1] if vertical else st[:, 0]
    pair = (lambda v, c: (v, c)) if vertical else (lambda v, c: (c, v))
    for k, (blk, rows) in enumerate(group):
        coord = -blk.stations[:, 1] if vertical else blk.stations[:, 0]  # what this survey read (one may be
        colour = STAGE_COLOURS[stages.index(blk.stage) % len(STAGE_COLOURS)] if staged else "#1f77b4"  # missing)
        mark = colour if staged else "k"
        band = colour if staged else "0.55"
        xc, sg = data.computed[rows] * MM, data.sigma[rows] * MM
        xm = data.measured[rows] * MM if data.measured is not None else None
        centre = xm if xm is not None else xc
        (ax.fill_betweenx if vertical else ax.fill_between)(coord, centre - 2 * sg, centre + 2 * sg, color=band,
                                                            alpha=0.18 if staged else 0.25, lw=0)
        if prof is not None and prof.line is not None and block.name not in data.no_line:
            line_reading = prof.stage_readings.get(blk.stage, prof.line_reading) if staged else prof.line_reading
            dense = (line_reading * MM, -prof.line[:, 1] if vertical else prof.line[:, 0])
            ax.plot(*pair(dense[0], dense[1]), color=colour, lw=1.2, alpha=0.7)
        ax.plot(*pair(xc, coord), ls="none", marker="o", ms=6, mfc="white", mec=colour, mew=1.6)
        if before is not None:
            ax.plot(*pair(before[rows] * MM, coord), ls="--", marker="s", ms=3.5, lw=1.2, color=BEFORE)
        if xm is not None:
            ax.plot(*pair(xm, coord), ls="none", marker="x", ms=7, mew=1.8, color=mark)
            _residual_texts(ax, coord, data.residual[rows], k,
                            lambda rv: "#b22222" if abs(rv) > 2 else (colour if staged else "0.25"), vertical)
    (ax.axvline if vertical else ax.axhline)(0, color="0.7", lw=0.7, zorder=0)
    if vertical:
        ax.invert_yaxis()
        ax.set_ylabel("depth below the surface [m]")
        ax.set_xlabel(f"{what} [mm]")
    else:
        ax.set_xlabel(X_WORDS)
        ax.set_ylabel(f"{what} [mm]")
        if data.measured is not None:
            lo_, hi_ = ax.get_ylim()
            rotated = len(labelled(data.residual[group[0][1]])) > 8
            per = 0.16 if rotated else 0.1
            ax.set_ylim(lo_, hi_ + (per + 0.02 + per * (len(group) - 1)) * (hi_ - lo_))  # room for the residuals
    return vertical


def _points(ax, block, group, data, prof, staged, stages, before) -> bool:
    vertical, pos, label = points_layout(block)
    comps = list(dict.fromkeys(lab.component for lab in block.labels))
    span = max(np.ptp(pos), 1.0)
    pair = (lambda c, v: (v, c)) if vertical else (lambda c, v: (c, v))
    for k, (blk, rows) in enumerate(group):
        colour = STAGE_COLOURS[stages.index(blk.stage) % len(STAGE_COLOURS)] if staged else "#1f77b4"
        mark = colour if staged else "k"
        shift = 0.012 * span * (k - (len(group) - 1) / 2)  # stages side by side at a point
        if prof is not None and prof.line is not None and prof.stage_line_displacement:
            u = prof.stage_line_displacement.get(blk.stage, prof.line_displacement)
            along = -prof.line[:, 1] if vertical else prof.line[:, 0]
            for comp in comps:
                ax.plot(*pair(along, u[:, 0 if comp == "ux" else 1] * MM), color=colour, lw=1.2, alpha=0.7,
                        ls=COMPONENT_MARK[comp]["ls"])
        xc, sg = data.computed[rows] * MM, data.sigma[rows] * MM
        pos = points_layout(blk)[1] if blk is not block else pos  # the points this survey read
        for comp in comps:
            sel = np.array([lab.component == comp for lab in blk.labels])
            p_ = pos[sel] + shift
            ax.plot(*pair(p_, xc[sel]), ls="none", marker="o", ms=6, mfc="white", mec=colour, mew=1.6)
            if before is not None:
                ax.plot(*pair(p_, before[rows][sel] * MM), ls="none", marker="s", ms=5, color=BEFORE)
            if data.measured is None:
                err = dict(xerr=2 * sg[sel]) if vertical else dict(yerr=2 * sg[sel])
                ax.errorbar(*pair(p_, xc[sel]), **err, ls="none", color="0.55", capsize=3, elinewidth=0.9,
                            zorder=1)
                continue
            xm = data.measured[rows][sel] * MM
            err = dict(xerr=2 * sg[sel]) if vertical else dict(yerr=2 * sg[sel])
            ax.errorbar(*pair(p_, xm), **err, ls="none", marker=COMPONENT_MARK[comp]["marker"], ms=7, mew=1.8,
                        color=mark, capsize=4, elinewidth=1.0)
            r_ = data.residual[rows][sel]
            side = 1 if k % 2 == 0 else -1  # two stages' residuals on either side of the point
            for q in labelled(r_) if len(group) <= 2 else np.flatnonzero(np.abs(r_) > 2):  # more: beyond ±2 only
                ax.annotate(f"r′={r_[q]:+.2f}", pair(p_[q], xm[q]), xytext=(0, 7 * side) if vertical else (6 * side, 0),
                            textcoords="offset points", fontsize=7.5,
                            va=("bottom" if side > 0 else "top") if vertical else "center",
                            ha="center" if vertical else ("left" if side > 0 else "right"),
                            color="#b22222" if abs(r_[q]) > 2 else (colour if staged else "0.25"),
                            bbox=dict(boxstyle="round,pad=0.1", fc="white", ec="none", alpha=0.7))
    what = (COMPONENT_WORDS[comps[0]] if len(comps) == 1
            else "displacement: u_y (+ up) solid, u_x (+ away from the axis) dotted")
    ax.axvline(0, color="0.7", lw=0.7, zorder=0) if vertical else ax.axhline(0, color="0.7", lw=0.7, zorder=0)
    if vertical:
        ax.invert_yaxis()
        ax.set_ylabel(label)
        ax.set_xlabel(f"{what} [mm]")
    else:
        ax.set_xlabel(label)
        ax.set_ylabel(f"{what} [mm]")
        lo_, hi_ = pos.min(), pos.max()
        pad = 0.08 * max(hi_ - lo_, 1.0)
        ax.set_xlim(lo_ - (2.2 if staged else 1.0) * pad, hi_ + 2.2 * pad)  # room for the residuals
    return vertical


def _chords(ax, block, group, data, staged, stages, before) -> None:
    m = len(group[0][1])
    for k, (blk, rows) in enumerate(group):
        colour = STAGE_COLOURS[stages.index(blk.stage) % len(STAGE_COLOURS)] if staged else "#1f77b4"
        mark = colour if staged else "k"
        kk = np.arange(1, len(rows) + 1) + 0.16 * (k - (len(group) - 1) / 2)
        xc, sg = data.computed[rows] * MM, data.sigma[rows] * MM
        ax.plot(kk, xc, ls="none", marker="o", ms=6, mfc="white", mec=colour, mew=1.6)
        if before is not None:
            ax.plot(kk, before[rows] * MM, ls="none", marker="s", ms=5, color=BEFORE)
        if data.measured is None:
            ax.errorbar(kk, xc, yerr=2 * sg, ls="none", color="0.55", capsize=3, elinewidth=0.9, zorder=1)
            continue
        xm, r_ = data.measured[rows] * MM, data.residual[rows]
        ax.errorbar(kk, xm, yerr=2 * sg, ls="none", marker="x", ms=7, mew=1.8, color=mark, capsize=4,
                    elinewidth=1.0)
        for k_, y_, rv in zip(kk, xm, r_):
            ax.annotate(f"r′={rv:+.2f}", (k_, y_), xytext=(6, 0), textcoords="offset points", fontsize=7.5,
                        va="center", color="#b22222" if abs(rv) > 2 else (colour if staged else "0.25"))
    ax.axhline(0, color="0.7", lw=0.7, zorder=0)
    ax.set_xticks(np.arange(1, m + 1))
    ax.set_xticklabels([f"chord {lab.station}" for lab in block.labels])
    ax.set_xlabel("chord")
    ax.set_ylabel("change of chord length (+ lengthening) [mm]")
    ax.set_xlim(0.4, m + 0.6)


def _load_cells(ax, block, group, data, staged, stages, before) -> None:
    """A load cell: the force of its prop or anchor [kN] (per metre run without a spacing) at each
    construction stage it was read at, measured ± 2σ and computed."""
    for blk, rows in group:
        k = stages.index(blk.stage)
        colour = STAGE_COLOURS[k % len(STAGE_COLOURS)] if staged else "#1f77b4"
        kk = np.full(len(rows), float(k))
        xc, sg = data.computed[rows], data.sigma[rows]
        ax.plot(kk, xc, ls="none", marker="o", ms=7, mfc="white", mec=colour, mew=1.6, zorder=4)
        if before is not None:
            ax.plot(kk, before[rows], ls="none", marker="s", ms=5, color=BEFORE)
        if data.measured is None:
            ax.errorbar(kk, xc, yerr=2 * sg, ls="none", color="0.55", capsize=3, elinewidth=0.9, zorder=1)
            continue
        xm, r_ = data.measured[rows], data.residual[rows]
        ax.errorbar(kk, xm, yerr=2 * sg, ls="none", marker="x", ms=7, mew=1.8, color=colour, capsize=4,
                    elinewidth=1.0, zorder=3)
        for k_, y_, rv in zip(kk, xm, r_):
            ax.annotate(f"r′={rv:+.2f}", (k_, y_), xytext=(8, 0), textcoords="offset points", fontsize=7.5,
                        va="center", color="#b22222" if abs(rv) > 2 else colour)
    ax.axhline(0, color="0.7", lw=0.7, zorder=0)
    ax.set_xticks(np.arange(len(stages)), [f"after '{st}'" for st in stages], rotation=20 if len(stages) > 3 else 0)
    ax.set_xlim(-0.5, len(stages) - 0.5)
    ax.set_xlabel("construction stage")
    ax.set_ylabel("axial force in the prop or anchor [kN]\n(prop compression +, anchor tension +)")


def _boundaries(ax, boundaries) -> None:
    """Boundaries within the panel's depth range (an instrument that does not reach one is not stretched)."""
    lims = ax.get_ylim()
    top, bottom = min(lims), max(lims)
    for b in boundaries:
        if not top <= b.depth <= bottom:
            continue
        if np.isfinite(b.low) and np.isfinite(b.high):
            ax.axhspan(b.low, b.high, color=BOUNDARY, alpha=0.15, lw=0, zorder=0)
        ax.axhline(b.depth, color=BOUNDARY, lw=1.3, ls="--", zorder=1)
    ax.set_ylim(lims)


def _draw(fig, data: _Readings, profiles: dict, before, boundaries, legend: list, legend_cols: int) -> None:
    groups = _groups(data.blocks)
    stages = list(dict.fromkeys(b.stage for b in data.blocks))
    staged = len(stages) > 1
    nb = len(groups)
    nrows, ncols = grid_shape(nb)
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False)).ravel()
    for ax, group in zip(axes, groups):
        block = group[0][0]
        prof = profiles.get(block.name)
        if block.integration is not None:
            depth_axis = _linewise(ax, block, group, data, prof, staged, stages, before)
        elif block.kind == "points":
            depth_axis = _points(ax, block, group, data, prof, staged, stages, before)
        elif block.kind == "load_cell":
            depth_axis = False
            _load_cells(ax, block, group, data, staged, stages, before)
        else:
            depth_axis = False
            _chords(ax, block, group, data, staged, stages, before)
        if depth_axis and boundaries:
            _boundaries(ax, boundaries)
        n_read = sum(len(rows) for _, rows in group)
        surveyed = any(blk.survey for blk, _ in group)  # dated surveys: one set a survey, named by its date
        sets = "surveys" if surveyed else "stages"
        title = f"{block.name} ({block.kind.replace('_', ' ')}, {n_read} reading{'s' if n_read != 1 else ''}" + (
            f" at {len(group)} {sets})" if len(group) > 1 else ")")
        if data.residual is not None:  # the misfit of each set in the title: never over the readings
            sums = [(f"{blk.stage} {blk.survey}" if blk.survey else blk.stage, data.residual[rows])
                    for blk, rows in group]
            title += "\n" + "\n".join((f"{stg}: " if len(sums) > 1 else "") +
                                      f"Σ r′² = {plain(float(r @ r))}, max |r′| = {plain(float(np.max(np.abs(r))))}"
                                      for stg, r in sums)
        ax.set_title(title, fontsize=10 if data.residual is None or len(group) == 1 else 9.5)
        ax.grid(True, color="0.92", lw=0.6)
        ax.set_axisbelow(True)
    spare = axes[nb:]
    for ax in spare:
        ax.set_axis_off()
    legend = legend + [Line2D([], [], color=BOUNDARY, lw=1.3, ls="--", label=b.label) for b in boundaries]
    if len(spare):  # the legend in the empty panel rather than below the figure
        spare[0].legend(handles=legend, loc="center", fontsize=8.5, frameon=False)
    else:
        fig.legend(handles=legend, loc="outside lower center", ncols=legend_cols, fontsize=8.5, frameon=False)


def _size(data: _Readings) -> tuple[float, float]:
    nrows, ncols = grid_shape(len(_groups(data.blocks)))
    staged = len({b.stage for b in data.blocks}) > 1
    return 4.9 * ncols + 0.6 + 0.5 * staged, 5.2 * nrows


def instruments_figure(res, exploration=None, before: np.ndarray | None = None, before_label: str = "before",
                       title: str | None = None, boundaries: list[Boundary] = ()) -> Figure:
    """Measured and computed readings along every instrument, +-2 sigma from diag C_x, and the
    model along each line where the exploration has it; one panel per instrument, with one colour
    per construction stage when it was read at several; `before` adds another model's readings
    (e.g. the baseline of a diagnosis) as a dashed red line; `boundaries` draws depths (an
    identified layer boundary with its interval) across the panels that have a depth axis."""
    f = res.fit
    stages = list(dict.fromkeys(b.stage for b in res.data.blocks))
    staged = len(stages) > 1
    identified = {n for n in res.parameters.names if is_instrument_term(n)}  # the line lacks them
    no_line = {b.name for b in res.data.blocks if any(n.endswith(f"[{b.name}]") for n in identified)}
    data = _Readings(list(res.data.blocks), f.x, np.sqrt(np.clip(np.diag(res.data.covariance), 0, None)),
                     res.data.measured, res.standardised, no_line)
    fig = new_figure(*_size(data))
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
    if any(len(labelled(res.standardised[rows])) < len(res.standardised[rows]) for _, rows in res.data.block_rows()):
        handles.append(Line2D([], [], ls="none", label=f"(residuals of more than {LABELS_MAX} stations: "
                                                       f"every k-th and all beyond ±2 written)"))
    if any(b.kind == "points" for b in res.data.blocks) and len(stages) > 2:
        handles.append(Line2D([], [], ls="none", label="(points read at more than two stages: residuals written "
                                                       "beyond ±2 only)"))
    if before is not None:
        handles.append(Line2D([], [], ls="--", marker="s", ms=3.5, lw=1.2, color=BEFORE, label=before_label))
    _draw(fig, data, exploration.profiles if exploration is not None else {}, before, list(boundaries), handles,
          2 if staged else 3)
    full_model_axes(fig, res.case)
    fig.suptitle(title or f"Measured and computed readings at the estimate (fit: {res.weighting} "
                          f"weighting; σ and whitened residuals r′ from the case's C_x)"
                          + (f"\nreadings accumulated up to each construction stage: {', '.join(stages)}"
                             if staged else ""), fontsize=10.5)
    return fig


X_WORDS = "horizontal distance from the symmetry axis x [m]"


def full_model_axes(fig, case) -> None:
    """A full model (a section with openings, `model: full`) has no symmetry axis: its x axes say x, and
    horizontal movements are along +x."""
    from geoback.reports.section import half_model

    if case is not None and not half_model(case):
        for ax in fig.axes:
            if ax.get_xlabel() == X_WORDS:
                ax.set_xlabel("x, horizontal position [m]")
            for get, put in ((ax.get_xlabel, ax.set_xlabel), (ax.get_ylabel, ax.set_ylabel)):
                text = get()
                if "away from the axis" in text or "towards the axis" in text:  # u_x: along +x there
                    put(text.replace("+ away from the axis", "+ towards +x").replace("+ towards the axis",
                                                                                      "+ towards -x"))


def predicted_figure(blocks, computed: np.ndarray, profiles: dict | None = None, name: str = "",
                     values_text: str = "") -> Figure:
    """The readings a forward run predicts along every instrument (``geoback simulate --plots``):
    the instruments figure without measured values, each prediction with the ±2σ its reading would
    scatter by (diag C_x of the case), the model along each line."""
    sigma = np.sqrt(np.clip(np.concatenate([np.diag(b.covariance) for b in blocks]), 0, None))
    data = _Readings(list(blocks), np.asarray(computed, float), sigma)
    stages = list(dict.fromkeys(b.stage for b in blocks))
    staged = len(stages) > 1
    fig = new_figure(*_size(data))
    if staged:
        handles = [Patch(color=STAGE_COLOURS[i % len(STAGE_COLOURS)], alpha=0.5,
                         label=f"after stage '{stg}' (line: model, o predicted at the stations)")
                   for i, stg in enumerate(stages)]
    else:
        handles = [Line2D([], [], color="#1f77b4", lw=1.2, alpha=0.7, label="model along the line"),
                   Line2D([], [], ls="none", marker="o", ms=6, mfc="white", mec="#1f77b4", mew=1.6,
                          label="predicted at the stations")]
    handles.append(Patch(color="0.55", alpha=0.25, label="± 2σ of a reading (σ from diag C_x of the case)"))
    _draw(fig, data, profiles or {}, None, [], handles, 3)
    who = f"{name}: " if name else ""
    fig.suptitle(f"{who}readings predicted by the model at the case's values"
                 + (f" ({values_text})" if values_text else "")
                 + (f"\naccumulated up to each construction stage: {', '.join(stages)}" if staged else ""),
                 fontsize=10.5)
    return fig
