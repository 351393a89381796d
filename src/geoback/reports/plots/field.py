"""The deformed mesh at the estimate, coloured by the displacement magnitude, with the instruments."""
from __future__ import annotations

import textwrap

import matplotlib
import numpy as np
from matplotlib import colormaps
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from matplotlib.tri import Triangulation

from geoback.reports import section
from geoback.reports.plots.common import HALO, estimate_text, new_figure, nice_factor

LINING = "#2a6f97"
FIELD_TARGET = 0.35  # the largest displacement is drawn as about this fraction of the tunnel radius
# (rounded down to a magnification of 1, 2 or 5 x 10^k; with openings, of the largest one's equivalent radius)


def field_figure(res, exploration) -> Figure:
    """Deformed mesh coloured by |u|, magnified, with the instruments (corner-node triangulation),
    after the last stage: with openings, the ground excavated by then left out and the linings standing
    then drawn apart."""
    f, case = res.fit, res.case
    mesh = exploration.field.mesh
    u = exploration.field.displacement  # (N, 2) nodal displacements
    R = section.size(case)
    cons = getattr(case, "construction", None)
    lining = getattr(cons, "lining", None) if cons is not None else None
    in_lining = (mesh.region == mesh.region_names.index(lining.name)) if (
        lining is not None and lining.name in mesh.region_names) else np.zeros(len(mesh.triangles), bool)
    void, standing = section.stage_state(case, mesh)
    in_lining = in_lining | (standing >= 0)
    umag = np.hypot(u[:, 0], u[:, 1])
    present = np.zeros(len(mesh.nodes), bool)  # nodes of what stands after the last stage
    present[mesh.triangles[~void].ravel()] = True
    umax = float(umag[present].max()) if present.any() else 0.0
    factor = nice_factor(FIELD_TARGET * R / umax) if umax > 0 else 1.0
    xy = mesh.nodes + factor * u
    T = Triangulation(xy[:, 0], xy[:, 1], mesh.triangles[:, :3])
    if in_lining.any() or void.any():  # the ground coloured by |u|, the lining drawn apart, the void left out
        T.set_mask(in_lining | void)
    stages = section.stage_names(case) if cons is not None else []
    if lining is not None:
        installed = next((st.name for st in cons.stages if st.install), None)
        lining_text = f"lining '{lining.name}' ({lining.thickness:g} m, installed at stage '{installed}'), deformed"
    else:
        put = section.installed_at(case) if section.has_openings(case) else {}
        walls = section.wall_names(case)
        shown = [mesh.band_names[i] for i in np.unique(standing[standing >= 0])]
        parts = [f"lining '{n}' (installed at '{put.get(n)}')" for n in shown if n not in walls]
        parts += [f"wall '{n}'" + (f" (installed at '{put[n]}')" if n in put else "") for n in shown if n in walls]
        lining_text = ", ".join(parts) + ", deformed"
    inst = []  # (block, displaced stations, displaced line or None)
    first: dict = {}
    for b in res.data.blocks:
        first.setdefault(b.name, b)  # the survey the exploration's profile holds the stations of
    for block in first.values():  # once per instrument (read at several stages)
        prof = exploration.profiles[block.name]
        stations = block.stations + factor * prof.station_displacement
        if block.kind == "convergence":  # a straight chord between its two (displaced) ends
            line_moved = stations
        elif prof.line is not None and block.kind != "points":  # (points: the stations alone)
            line_moved = prof.line + factor * prof.line_displacement
        else:
            line_moved = None
        inst.append((block, stations, line_moved))
    full_x, full_y, zx, zy, ratios = section.frames(case)
    fig = new_figure(*section.figure_size(ratios, 1.6))
    axF, axZ = fig.subplots(1, 2, width_ratios=ratios)
    top = umax * 1e3 if umax > 0 else 1.0
    levels = MaxNLocator(nbins=14).tick_values(0.0, top)
    norm = matplotlib.colors.Normalize(0.0, levels[-1])
    cmap = colormaps["magma_r"]
    colours = colormaps["tab10"]
    for ax, zoom in ((axF, False), (axZ, True)):
        tpc = ax.tricontourf(T, umag * 1e3, levels=levels, cmap=cmap, norm=norm)
        tpc.set_rasterized(True)
        ax.triplot(T, color="k", lw=0.3 if zoom else 0.2, alpha=0.3, rasterized=True)
        if in_lining.any():
            tri = xy[mesh.triangles[in_lining][:, :3]]
            ax.add_collection(PolyCollection(tri, facecolors=LINING, edgecolors=LINING, linewidths=0.3, zorder=3,
                                             label=lining_text))
        section.draw_section(ax, case)
        ax.plot(*section.boundary_line(case), color="0.35", lw=0.9, ls=":", label="model boundary before excavation")
        for li, layer in enumerate(res.case.ground.layers[1:]):
            ax.axhline(-layer.top, color="0.15", lw=0.9, ls=(0, (6, 3)), zorder=3,
                       label="layer interface (before excavation)" if li == 0 else None)
            if not zoom:
                ax.text(section.layer_label_x(case), -layer.top, f"{layer.name} ↓", ha="right", va="top",
                        fontsize=7.5, path_effects=HALO, zorder=3)
        for k, (block, P, line) in enumerate(inst):
            c = colours(k % 10)
            if line is not None:
                ax.plot(line[:, 0], line[:, 1], color=c, lw=1.6 if zoom else 1.2, path_effects=HALO)
            ax.plot(P[:, 0], P[:, 1], ls="none", marker="s" if block.kind == "load_cell" else "o",
                    ms=5.5 if zoom else 4, mfc=c, mec="white", mew=0.8, label=section.instrument_label(case, block),
                    zorder=5)
        if zoom:  # arrows: direction of movement (true displacement, scaled with the colour bar)
            sel = ((mesh.nodes[:, 0] >= zx[0]) & (mesh.nodes[:, 0] <= zx[1]) & (mesh.nodes[:, 1] >= zy[0])
                   & (mesh.nodes[:, 1] <= zy[1])
                   & (np.arange(len(mesh.nodes)) < mesh.triangles[:, :3].max() + 1))
            corner = np.zeros(len(mesh.nodes), bool)
            corner[mesh.triangles[~(in_lining | void), :3].ravel()] = True  # the ground's corner nodes
            sel &= corner & (umag > 0.15 * umax)
            idx = np.flatnonzero(sel)
            if len(idx) > 90:
                idx = idx[np.linspace(0, len(idx) - 1, 90).astype(int)]
            ax.quiver(xy[idx, 0], xy[idx, 1], u[idx, 0], u[idx, 1], color="white", alpha=0.9, width=0.006,
                      scale=umax * 14, scale_units="width", zorder=4)
        ax.set_aspect("equal")
        ax.set_xlabel(section.x_label(case))
        ax.set_ylabel("elevation y, ground surface at 0 [m]")
    axF.set_xlim(*full_x)
    axF.set_ylim(*full_y)
    axF.set_title(section.whole_title(case), fontsize=10)
    axZ.set_xlim(*zx)
    axZ.set_ylim(*zy)
    axZ.set_title(f"{section.zoom_title(case)} (arrows: direction of movement)", fontsize=10)
    if section.has_openings(case):  # below the panels: the openings may lie anywhere in the section
        handles, texts = axF.get_legend_handles_labels()
        fig.legend(handles, texts, loc="outside lower center", ncols=min(3, len(handles)), fontsize=8, frameon=False)
    else:
        axF.legend(loc="lower right", fontsize=8, framealpha=0.92)
    cb = fig.colorbar(tpc, ax=[axF, axZ], shrink=0.9, pad=0.015, aspect=30)
    cb.set_label("displacement magnitude |u| [mm]")
    est = textwrap.fill(f"({estimate_text(res.parameters, f.p)})", 110)
    when = (f" after stage '{stages[-1]}' (the last of {len(stages)}: {', '.join(stages)})" if len(stages) > 1
            else f" after stage '{stages[0]}'" if stages else "")
    size_words = (f"the tunnel radius R = {R:g} m" if not section.has_openings(case) else
                  f"the largest opening's equivalent radius R = {R:.3g} m")
    head = textwrap.fill(f"{res.name}: excavation-induced displacements{when} at the estimate", 110)
    fig.suptitle(f"{head}\n{est}\n"
                 f"max |u| = {umax * 1e3:.1f} mm; deformation magnified ×{factor:g} "
                 f"(max |u| drawn as {factor * umax / R:.0%} of {size_words})", fontsize=10.5)
    return fig

