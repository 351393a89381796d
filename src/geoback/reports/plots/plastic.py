"""The plastic zone: the ground coloured by its equivalent plastic strain after the last stage and the
zone's boundary after every stage, in metres. A circular tunnel's half-model is drawn with its wall and
the crown, springline and invert named; a section with openings (any shape, a wall and props, a
heading and bench) with the openings' outlines, the ground excavated by the last stage left out, the
linings and walls standing then, and every stage's zone on the ground standing after that stage."""
from __future__ import annotations

import textwrap

import numpy as np
from matplotlib import colormaps
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure
from matplotlib.tri import Triangulation

from geoback.physics.plastic_zone import AXIS
from geoback.reports import section
from geoback.reports.plots.common import HALO, estimate_text, new_figure

STAGE_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#17becf")


def _nodal(mesh, cell: np.ndarray) -> np.ndarray:
    """Cell values averaged onto the corner nodes (for contours)."""
    corners = mesh.triangles[:, :3]
    total = np.bincount(corners.ravel(), weights=np.repeat(cell, 3), minlength=len(mesh.nodes))
    count = np.bincount(corners.ravel(), minlength=len(mesh.nodes))
    return np.where(count > 0, total / np.maximum(count, 1), 0.0)


def _extent_words(zone, s) -> str:
    """How far a stage's zone reaches, as its legend says it."""
    if zone.about == AXIS:
        return f"reaches {s.max_radius:.2f} m from the axis ({s.max_radius / zone.radius:.2f} R)"
    return f"{s.top_depth:.1f} to {s.bottom_depth:.1f} m deep, {s.area:.3g} m²"


def plastic_zone_figure(zone, res=None, name: str | None = None, case=None, at: str | None = None) -> Figure:
    """`zone`: a plastic_zone.PlasticZone (from the exploration or a forward run); `res`: the
    identification it belongs to (for the title and the case), or None (a forward run at the case's
    values, of the case `name`; `case` the case, needed to draw a section with openings); `at`: the
    title's words for the values (default: at the estimate, or at the case's values)."""
    case = res.case if res is not None else case
    openings = case is not None and section.has_openings(case)
    mesh = zone.mesh
    fig = new_figure(6.6, 8.6) if not openings else new_figure(*_size(case, zone))
    ax = fig.subplots()
    T = Triangulation(mesh.nodes[:, 0], mesh.nodes[:, 1], mesh.triangles[:, :3])
    last = len(zone.stages) - 1
    gone = np.zeros(len(mesh.triangles), bool)
    if openings:  # the ground as it stands after the last stage: the void and the linings left out of it
        void, standing = section.stage_state(case, mesh)
        gone = void | (standing >= 0)
        T.set_mask(gone)
    strain = 100 * zone.cell_plastic_strain[last]
    top = float(strain[~gone].max()) if zone.any and (~gone).any() else 1.0
    cmap = colormaps["YlOrRd"].with_extremes(bad="white")  # elastic ground white
    pc = ax.tripcolor(T, facecolors=np.ma.masked_where(zone.cell_yielded[last] <= 0, strain), cmap=cmap,
                      vmin=0.0, vmax=top if top > 0 else 1.0, rasterized=True)
    ax.triplot(T, color="k", lw=0.25, alpha=0.25, rasterized=True)
    handles = []
    for k, s in enumerate(zone.stages):
        c = STAGE_COLOURS[k % len(STAGE_COLOURS)]
        # (a section's stage releases the whole of what it excavates unless the case says otherwise)
        release = "" if openings and s.release >= 1 else f" (release {s.release:.2g})"
        if not s.yielded_points:
            handles.append(ax.plot([], [], ls="none", label=f"after '{s.stage}'{release}: the ground stays elastic")[0])
            continue
        Tk = T
        if openings:  # the zone on the ground standing after that stage
            void_k, standing_k = section.stage_state(case, mesh, k)
            Tk = Triangulation(mesh.nodes[:, 0], mesh.nodes[:, 1], mesh.triangles[:, :3], mask=void_k | (standing_k >= 0))
        ax.tricontour(Tk, _nodal(mesh, zone.cell_yielded[k]), levels=[0.5], colors=[c],
                      linewidths=2.0 if k == last else 1.3, linestyles="-" if k == last else "--")
        handles.append(ax.plot([], [], color=c, lw=2.0 if k == last else 1.3, ls="-" if k == last else "--",
                               label=f"plastic zone after '{s.stage}'{release}: "
                                     f"{_extent_words(zone, s)}")[0])
    if openings:
        _draw_openings(ax, case, mesh, standing, zone, handles)
    else:
        _draw_tunnel(ax, zone, handles)
    ax.set_aspect("equal")
    ax.set_ylabel("elevation y, ground surface at 0 [m]")
    if zone.any:
        cb = fig.colorbar(pc, ax=ax, shrink=0.85, pad=0.02, aspect=30)
        cb.set_label(f"equivalent plastic strain after '{zone.stages[last].stage}' [%]")
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.07), fontsize=8, frameon=False)
    who = f"{res.name}: " if res is not None else f"{name}: " if name else ""
    at = at or ("at the estimate" if res is not None else "at the case's values")
    around = section.zoom_title(case).lower() if case is not None else "around the tunnel"
    fitted = list(res.parameters.names) if res is not None else []
    words = ([estimate_text(res.parameters, res.fit.p)] if res is not None else []) + _strength_words(zone.values, fitted)
    sub = textwrap.fill("(" + "; ".join(words) + ")", 90) if words else ""
    state = "" if zone.any else " - the ground stays elastic"
    fig.suptitle(f"{who}plastic zone {around} {at}{state}" + (f"\n{sub}" if sub else ""), fontsize=10.5)
    return fig


def _strength_words(values: dict, fitted: list) -> list[str]:
    """The Mohr-Coulomb strength of every layer that may yield, the values not fitted: e.g. "phi' = 30 deg,
    psi = 0 deg in 'soft' (not fitted)", or with nothing fitted "'marl': c' = 40 kPa, phi' = 30 deg, psi = 5 deg"."""
    out = []
    for layer in sorted(k[4:-1] for k in values if k.startswith("phi[")):
        parts = [(f"c[{layer}]", "c'", "kPa"), (f"phi[{layer}]", "phi'", "deg"), (f"psi[{layer}]", "psi", "deg")]
        held = [f"{word} = {values[k]:.4g} {unit}" for k, word, unit in parts if k in values and k not in fitted]
        if held and fitted:
            out.append(f"{', '.join(held)} in '{layer}' (not fitted)")
        elif held:
            out.append(f"'{layer}': {', '.join(held)}")
    return out


def _draw_tunnel(ax, zone, handles) -> None:
    """A circular tunnel's half-model: its wall, the crown, springline and invert, the symmetry axis and
    the ground surface; the frame about the tunnel and the zone."""
    R = zone.radius
    cx, cy = zone.centre
    reach = max([s.max_radius for s in zone.stages if s.yielded_points] + [R])
    half = max(2.2 * R, 1.35 * reach)
    theta = np.linspace(-np.pi / 2, np.pi / 2, 200)
    handles.append(ax.plot(cx + R * np.cos(theta), cy + R * np.sin(theta), color="0.1", lw=1.6,
                           label=f"tunnel wall (R = {R:g} m)")[0])
    ax.axvline(0.0, color="0.5", lw=0.9, ls="-.")
    if cy + half > -0.02 * half:
        ax.axhline(0.0, color="0.35", lw=1.0)
        ax.text(half * 0.98, 0.0, "ground surface", ha="right", va="bottom", fontsize=8, path_effects=HALO)
    for a, where in ((0, "crown"), (90, "springline"), (180, "invert")):
        t = np.radians(a)
        ax.text(cx + 0.9 * R * np.sin(t) + 0.04 * R, cy + 0.86 * R * np.cos(t), where, fontsize=8, color="0.3",
                ha="right" if a == 90 else "left", va="center")
    ax.set_xlim(-0.03 * half, half)
    ax.set_ylim(cy - half, min(cy + half, 0.06 * half))
    ax.set_xlabel("x, distance from the symmetry axis [m]")


def _frame(case, zone) -> tuple[tuple, tuple]:
    """The zoom of the section's figures about the openings, widened to hold the plastic zone of every
    stage with a margin of a tenth of its span."""
    _, _, zx, zy, _ = section.frames(case)
    x0, x1, depth = section.box(case)
    yielded = np.any(zone.cell_yielded > 0, axis=0)
    if not yielded.any():
        return zx, zy
    xy = zone.mesh.nodes[np.unique(zone.mesh.triangles[yielded, :3])]
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    pad = 0.1 * max(hi - lo)
    zx = (min(zx[0], max(x0, lo[0] - pad)), max(zx[1], min(x1, hi[0] + pad)))
    zy = (min(zy[0], max(-depth, lo[1] - pad)), zy[1])
    return zx, zy


def _size(case, zone) -> tuple[float, float]:
    zx, zy = _frame(case, zone)
    aspect = (zx[1] - zx[0]) / (zy[1] - zy[0])
    return (6.6, 8.6) if aspect <= 0.75 else (11.0, min(8.6, 3.0 + 7.0 / aspect))  # (a tall frame as the tunnel's)


def _draw_openings(ax, case, mesh, standing, zone, handles) -> None:
    """A section with openings: their outlines and cut lines, the linings and walls standing after the
    last stage, the ground surface; the frame about the openings and the zone."""
    stages = zone.stages
    if (standing >= 0).any():
        tri = mesh.nodes[mesh.triangles[standing >= 0][:, :3]]
        ax.add_collection(PolyCollection(tri, facecolors=section.LINING, edgecolors=section.LINING, linewidths=0.3, zorder=3))
        names = [mesh.band_names[i] for i in np.unique(standing[standing >= 0])]
        walls = set(section.wall_names(case))
        words = ", ".join(f"wall '{n}'" if n in walls else f"lining '{n}'" for n in names)
        handles.append(ax.plot([], [], color=section.LINING, lw=5, label=f"{words}, standing after '{stages[-1].stage}'")[0])
    section.draw_section(ax, case, label=False, colour="0.1")
    handles.append(ax.plot([], [], color="0.1", lw=1.3, ls="--", label="openings' walls before excavation")[0])
    zx, zy = _frame(case, zone)
    if section.half_model(case):
        ax.axvline(0.0, color="0.5", lw=0.9, ls="-.")
    if zy[1] > 0:
        ax.axhline(0.0, color="0.35", lw=1.0)
        ax.text(zx[1] - 0.02 * (zx[1] - zx[0]), 0.0, "ground surface", ha="right", va="top", fontsize=8,
                path_effects=HALO)
    ax.set_xlim(*zx)
    ax.set_ylim(*zy)
    ax.set_xlabel(section.x_label(case))
