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

from geoback.reports.plots.common import HALO, section_frames, estimate_text, new_figure, nice_factor

LINING = "#2a6f97"
FIELD_TARGET = 0.35  # the largest displacement is drawn as about this fraction of the tunnel radius
# (rounded down to a magnification of 1, 2 or 5 x 10^k)


def field_figure(res, exploration) -> Figure:
    """Deformed mesh coloured by |u|, magnified, with the instruments (corner-node triangulation)."""
    f, g = res.fit, res.case.geometry
    mesh = exploration.field.mesh
    u = exploration.field.displacement  # (N, 2) nodal displacements
    umag = np.hypot(u[:, 0], u[:, 1])
    umax = float(umag.max()) if umag.size else 0.0
    factor = nice_factor(FIELD_TARGET * g.radius / umax) if umax > 0 else 1.0
    xy = mesh.nodes + factor * u
    T = Triangulation(xy[:, 0], xy[:, 1], mesh.triangles[:, :3])
    cons = getattr(res.case, "construction", None)
    lining = cons.lining if cons is not None else None
    in_lining = (mesh.region == mesh.region_names.index(lining.name)) if (
        lining is not None and lining.name in mesh.region_names) else np.zeros(len(mesh.triangles), bool)
    if in_lining.any():  # the ground coloured by |u|, the lining drawn apart
        T.set_mask(in_lining)
    stages = [st.name for st in cons.stages] if cons is not None else []
    installed = next((st.name for st in cons.stages if st.install), None) if cons is not None else None
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
    cx, cy, R = 0.0, -g.axis_depth, g.radius
    full_x, full_y, zx, zy, ratios = section_frames(g)
    fig = new_figure(4.9 * (ratios[0] + ratios[1]) + 1.6, 5.6)
    axF, axZ = fig.subplots(1, 2, width_ratios=ratios)
    top = umax * 1e3 if umax > 0 else 1.0
    levels = MaxNLocator(nbins=14).tick_values(0.0, top)
    norm = matplotlib.colors.Normalize(0.0, levels[-1])
    cmap = colormaps["magma_r"]
    colours = colormaps["tab10"]
    theta = np.linspace(-np.pi / 2, np.pi / 2, 200)
    for ax, zoom in ((axF, False), (axZ, True)):
        tpc = ax.tricontourf(T, umag * 1e3, levels=levels, cmap=cmap, norm=norm)
        tpc.set_rasterized(True)
        ax.triplot(T, color="k", lw=0.3 if zoom else 0.2, alpha=0.3, rasterized=True)
        if in_lining.any():
            tri = xy[mesh.triangles[in_lining][:, :3]]
            ax.add_collection(PolyCollection(tri, facecolors=LINING, edgecolors=LINING, linewidths=0.3, zorder=3,
                                             label=f"lining '{lining.name}' ({lining.thickness:g} m, installed at "
                                                   f"stage '{installed}'), deformed"))
        ax.plot(cx + R * np.cos(theta), cy + R * np.sin(theta), color="#1f77b4", lw=1.4, ls="--",
                label="tunnel wall before excavation")
        ax.plot([0, g.width, g.width, 0, 0], [0, 0, -g.depth, -g.depth, 0], color="0.35", lw=0.9, ls=":",
                label="model boundary before excavation")
        for li, layer in enumerate(res.case.ground.layers[1:]):
            ax.axhline(-layer.top, color="0.15", lw=0.9, ls=(0, (6, 3)), zorder=3,
                       label="layer interface (before excavation)" if li == 0 else None)
            if not zoom:
                ax.text(0.99 * g.width, -layer.top, f"{layer.name} ↓", ha="right", va="top", fontsize=7.5,
                        path_effects=HALO, zorder=3)
        for k, (block, P, line) in enumerate(inst):
            c = colours(k % 10)
            if line is not None:
                ax.plot(line[:, 0], line[:, 1], color=c, lw=1.6 if zoom else 1.2, path_effects=HALO)
            ax.plot(P[:, 0], P[:, 1], ls="none", marker="o", ms=5.5 if zoom else 4, mfc=c, mec="white", mew=0.8,
                    label=f"{block.name} ({block.kind}) stations", zorder=5)
        if zoom:  # arrows: direction of movement (true displacement, scaled with the colour bar)
            sel = ((mesh.nodes[:, 0] <= zx[1]) & (mesh.nodes[:, 1] >= zy[0]) & (mesh.nodes[:, 1] <= zy[1])
                   & (np.arange(len(mesh.nodes)) < mesh.triangles[:, :3].max() + 1))
            corner = np.zeros(len(mesh.nodes), bool)
            corner[mesh.triangles[~in_lining, :3].ravel()] = True  # the ground's corner nodes
            sel &= corner & (umag > 0.15 * umax)
            idx = np.flatnonzero(sel)
            if len(idx) > 90:
                idx = idx[np.linspace(0, len(idx) - 1, 90).astype(int)]
            ax.quiver(xy[idx, 0], xy[idx, 1], u[idx, 0], u[idx, 1], color="white", alpha=0.9, width=0.006,
                      scale=umax * 14, scale_units="width", zorder=4)
        ax.set_aspect("equal")
        ax.set_xlabel("x, distance from the symmetry axis [m]")
        ax.set_ylabel("elevation y, ground surface at 0 [m]")
    axF.set_xlim(*full_x)
    axF.set_ylim(*full_y)
    axF.set_title("Whole model (half section, symmetry axis at x = 0)", fontsize=10)
    axZ.set_xlim(*zx)
    axZ.set_ylim(*zy)
    axZ.set_title("Around the tunnel (arrows: direction of movement)", fontsize=10)
    axF.legend(loc="lower right", fontsize=8, framealpha=0.92)
    cb = fig.colorbar(tpc, ax=[axF, axZ], shrink=0.9, pad=0.015, aspect=30)
    cb.set_label("displacement magnitude |u| [mm]")
    est = textwrap.fill(f"({estimate_text(res.parameters, f.p)})", 110)
    when = (f" after stage '{stages[-1]}' (the last of {len(stages)}: {', '.join(stages)})" if len(stages) > 1
            else f" after stage '{stages[0]}'" if stages else "")
    fig.suptitle(f"{res.name}: excavation-induced displacements{when} at the estimate\n{est}\n"
                 f"max |u| = {umax * 1e3:.1f} mm; deformation magnified ×{factor:g} "
                 f"(max |u| drawn as {factor * umax / R:.0%} of the tunnel radius R = {R:g} m)", fontsize=10.5)
    return fig

