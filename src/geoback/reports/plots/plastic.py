"""The plastic zone around the tunnel: the ground coloured by its equivalent plastic strain after the
last stage, the zone's boundary after every stage, the tunnel and the ground surface, in metres."""
from __future__ import annotations

import textwrap

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.tri import Triangulation

from geoback.reports.plots.common import HALO, estimate_text, new_figure

STAGE_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#17becf")


def _nodal(mesh, cell: np.ndarray) -> np.ndarray:
    """Cell values averaged onto the corner nodes (for contours)."""
    corners = mesh.triangles[:, :3]
    total = np.bincount(corners.ravel(), weights=np.repeat(cell, 3), minlength=len(mesh.nodes))
    count = np.bincount(corners.ravel(), minlength=len(mesh.nodes))
    return np.where(count > 0, total / np.maximum(count, 1), 0.0)


def plastic_zone_figure(zone, res=None, name: str | None = None) -> Figure:
    """`zone`: a plastic_zone.PlasticZone (from the exploration or a forward run); `res`: the
    identification it belongs to (for the title), or None (a forward run at the case's values, of
    the case `name`)."""
    mesh, R = zone.mesh, zone.radius
    cx, cy = zone.centre
    reach = max([s.max_radius for s in zone.stages if s.yielded_points] + [R])
    half = max(2.2 * R, 1.35 * reach)
    fig = new_figure(6.6, 8.6)
    ax = fig.subplots()
    T = Triangulation(mesh.nodes[:, 0], mesh.nodes[:, 1], mesh.triangles[:, :3])
    last = len(zone.stages) - 1
    strain = 100 * zone.cell_plastic_strain[last]
    top = float(strain.max()) if zone.any else 1.0
    cmap = colormaps["YlOrRd"].with_extremes(bad="white")  # elastic ground white
    pc = ax.tripcolor(T, facecolors=np.ma.masked_where(zone.cell_yielded[last] <= 0, strain), cmap=cmap,
                      vmin=0.0, vmax=top if top > 0 else 1.0, rasterized=True)
    ax.triplot(T, color="k", lw=0.25, alpha=0.25, rasterized=True)
    handles = []
    for k, s in enumerate(zone.stages):
        if not s.yielded_points:
            continue
        c = STAGE_COLOURS[k % len(STAGE_COLOURS)]
        ax.tricontour(T, _nodal(mesh, zone.cell_yielded[k]), levels=[0.5], colors=[c],
                      linewidths=2.0 if k == last else 1.3, linestyles="-" if k == last else "--")
        handles.append(ax.plot([], [], color=c, lw=2.0 if k == last else 1.3, ls="-" if k == last else "--",
                               label=f"plastic zone after '{s.stage}' (release {s.release:.2g}): reaches "
                                     f"{s.max_radius:.2f} m from the axis ({s.max_radius / R:.2f} R)")[0])
    theta = np.linspace(-np.pi / 2, np.pi / 2, 200)
    handles.append(ax.plot(cx + R * np.cos(theta), cy + R * np.sin(theta), color="0.1", lw=1.6,
                           label=f"tunnel wall (R = {R:g} m)")[0])
    ax.axvline(0.0, color="0.5", lw=0.9, ls="-.")
    if cy + half > -0.02 * half:
        ax.axhline(0.0, color="0.35", lw=1.0)
        ax.text(half * 0.98, 0.0, "ground surface", ha="right", va="bottom", fontsize=8, path_effects=HALO)
    for a, name in ((0, "crown"), (90, "springline"), (180, "invert")):
        t = np.radians(a)
        ax.text(cx + 0.9 * R * np.sin(t) + 0.04 * R, cy + 0.86 * R * np.cos(t), name, fontsize=8, color="0.3",
                ha="right" if a == 90 else "left", va="center")
    ax.set_aspect("equal")
    ax.set_xlim(-0.03 * half, half)
    ax.set_ylim(cy - half, min(cy + half, 0.06 * half))
    ax.set_xlabel("x, distance from the symmetry axis [m]")
    ax.set_ylabel("elevation y, ground surface at 0 [m]")
    if zone.any:
        cb = fig.colorbar(pc, ax=ax, shrink=0.85, pad=0.02, aspect=30)
        cb.set_label(f"equivalent plastic strain after '{zone.stages[last].stage}' [%]")
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.07), fontsize=8, frameon=False)
    who = f"{res.name}: " if res is not None else f"{name}: " if name else ""
    at = "at the estimate" if res is not None else "at the case's values"
    sub = textwrap.fill(f"({estimate_text(res.parameters, res.fit.p)})", 90) if res is not None else ""
    state = "" if zone.any else " - the ground stays elastic"
    fig.suptitle(f"{who}plastic zone around the tunnel {at}{state}" + (f"\n{sub}" if sub else ""), fontsize=10.5)
    return fig
