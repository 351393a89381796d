"""The finite-element mesh: the whole model and a zoom on the tunnel, the elements coloured by layer
(a lining apart), the tunnel wall, the layer interfaces and the instruments' stations, in metres.
A section with openings is drawn before construction: the ground each stage excavates shaded by part,
the linings' bands in the lining's colour, the openings' walls and cut lines (``section.py``)."""
from __future__ import annotations

import numpy as np
from matplotlib import colormaps
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from geoback.reports import section
from geoback.reports.plots.common import HALO, new_figure

LAYER_COLOURS = ("#e8d8b0", "#c9d9a8", "#b9cfe0", "#e3c0c0", "#d6c6e6", "#c8e0d8", "#efd9c2", "#d0d0d0")
LINING = "#2a6f97"
WALL = "#7f4f24"  # a retaining wall's band
PART_COLOURS = ("#f4f4f4", "#dcdcdc", "#ececc8", "#d8e4ec", "#ead8e4")  # the ground of each part, before it is dug


def mesh_figure(mesh, case, blocks=(), name: str | None = None) -> Figure:
    """`mesh`: a physics.mesh.Mesh (of the ground; with the lining's elements when it comes from a
    field); `case`: the case (geometry, layers, the lining's name); `blocks`: the instruments
    (observation.InstrumentBlock), drawn at their stations."""
    g = case.geometry
    cons = getattr(case, "construction", None)
    lining = cons.lining.name if cons is not None and getattr(cons, "lining", None) is not None else None
    corners = mesh.triangles[:, :3]
    tri = mesh.nodes[corners]
    colour = np.array([LINING if mesh.region_names[r] == lining else LAYER_COLOURS[r % len(LAYER_COLOURS)]
                       for r in mesh.region], dtype=object)
    part = getattr(mesh, "part", None)
    band = getattr(mesh, "band", None)
    sectioned = part is not None and section.has_openings(case)
    if sectioned:
        for k in range(len(mesh.part_names)):
            colour[part == k] = PART_COLOURS[k % len(PART_COLOURS)]
        walls = section.wall_names(case)
        for k, n in enumerate(mesh.band_names):
            colour[band == k] = WALL if n in walls else LINING
    full_x, full_y, zx, zy, ratios = section.frames(case)
    fig = new_figure(*section.figure_size(ratios, 0.6))
    axF, axZ = fig.subplots(1, 2, width_ratios=ratios)
    marks = colormaps["tab10"]
    seen = {}
    for b in blocks:
        seen.setdefault(b.name, b)
    for ax, zoom in ((axF, False), (axZ, True)):
        ax.add_collection(PolyCollection(tri, facecolors=list(colour), edgecolors="0.25",
                                         linewidths=0.35 if zoom else 0.2, rasterized=True))
        section.draw_section(ax, case, label=False, colour="k")
        for layer in case.ground.layers[1:]:
            ax.axhline(-layer.top, color="0.15", lw=0.9, ls=(0, (6, 3)), zorder=3)
        for k, b in enumerate(seen.values()):
            P = b.stations if b.kind != "convergence" else b.points
            if b.reference is not None:  # a linewise instrument: its line from the reference end
                L = np.vstack([b.reference, P])
                ax.plot(L[:, 0], L[:, 1], color=marks(k % 10), lw=1.0, zorder=4)
            ax.plot(P[:, 0], P[:, 1], ls="-" if b.kind == "convergence" else "none",
                    marker="s" if b.kind == "load_cell" else "o", ms=5 if zoom else 3.5, color=marks(k % 10),
                    mec="white", mew=0.6, zorder=5)
        ax.set_aspect("equal")
        ax.set_xlabel(section.x_label(case))
        ax.set_ylabel("elevation y, ground surface at 0 [m]")
    axF.set_xlim(*full_x)
    axF.set_ylim(*full_y)
    axZ.set_xlim(*zx)
    axZ.set_ylim(*zy)
    axF.set_title(section.whole_title(case), fontsize=10)
    axZ.set_title(section.zoom_title(case), fontsize=10)
    depth = section.box(case)[2]
    for layer in case.ground.layers:
        axF.text(section.layer_label_x(case), -layer.top - 0.01 * depth, f"{layer.name} ↓", ha="right", va="top",
                 fontsize=7.5, path_effects=HALO, zorder=4)
    handles = [Patch(facecolor=LINING if n == lining else LAYER_COLOURS[i % len(LAYER_COLOURS)], edgecolor="0.25",
                     label=(f"lining '{n}'" if n == lining else f"layer '{n}'")) for i, n in enumerate(mesh.region_names)]
    when = ""
    if sectioned:
        dug = {r: s.name for s in _steps(case) for r in s.excavate}
        handles += [Patch(facecolor=PART_COLOURS[k % len(PART_COLOURS)], edgecolor="0.25",
                          label=f"'{n}', excavated at stage '{dug.get(n, 'never')}'") for k, n in enumerate(mesh.part_names)]
        put = section.installed_at(case)
        walls = section.wall_names(case)
        bands = ", ".join(f"'{n}' installed at '{put.get(n, 'never')}'" for n in mesh.band_names if n not in walls)
        handles += [Patch(facecolor=LINING, edgecolor="0.25", label=f"linings' bands ({bands})")] if bands else []
        handles += [Patch(facecolor=WALL, edgecolor="0.25",
                          label=f"retaining wall '{n}' (" + (f"installed at '{put[n]}'" if n in put else
                                                             "in place before construction") + ")")
                    for n in mesh.band_names if n in walls]
        when = (" (before construction: every part, lining and wall band meshed)" if walls else
                " (before construction: every part and lining band meshed)")
    handles += [axF.plot([], [], ls="none", marker="s" if b.kind == "load_cell" else "o", ms=5, color=marks(k % 10),
                         mec="white", label=section.instrument_label(case, b))[0] for k, b in enumerate(seen.values())]
    fig.legend(handles=handles, loc="outside lower center", ncols=min(4, len(handles)), fontsize=8, frameon=False)
    kind = "quadratic" if mesh.order == 2 else "linear"
    dofs = 2 * len(mesh.nodes)
    fig.suptitle(f"{name or case.name}: finite-element mesh{when} - {len(mesh.triangles):,} {kind} triangles, "
                 f"{len(mesh.nodes):,} nodes, {dofs:,} degrees of freedom", fontsize=10.5)
    return fig


def _steps(case):
    from geoback.case.sequence import Sequence

    return Sequence.of(case).steps
