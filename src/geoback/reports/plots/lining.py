"""Thrust, bending moment and shear around the lining, per construction stage: the figure a designer
pastes into a report. Left: the lining in section with the bending-moment diagram drawn on the
tension side after the last stage; right: N, M and V against the angle from the crown (arc length
along the centreline on the top axis), one curve per stage."""
from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from geoback.reports.plots.common import HALO, new_figure

STAGE_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#17becf")


def _nice(v: float) -> str:
    return f"{v:.3g}"


def lining_figure(forces, res=None) -> Figure:
    """`forces`: a lining.LiningForces (from the exploration or a forward run); `res`: the
    identification it belongs to (for the title), or None."""
    fig = new_figure(12.5, 7.4)
    grid = fig.add_gridspec(3, 2, width_ratios=[1.0, 1.45])
    axR = fig.add_subplot(grid[:, 0])
    axN, axM, axV = (fig.add_subplot(grid[i, 1]) for i in range(3))
    ang = forces.angle
    last = len(forces.stages) - 1
    for k, stage in enumerate(forces.stages):
        c = STAGE_COLOURS[k % len(STAGE_COLOURS)]
        for ax, y in ((axN, forces.N[k]), (axM, forces.M[k]), (axV, forces.V[k])):
            ax.plot(ang, y, color=c, lw=1.6 if k == last else 1.1, ls="-" if k == last else "--",
                    label=f"after stage '{stage}'")
    for ax, what in ((axN, "hoop thrust N [kN/m]\n(compression +)"),
                     (axM, "bending moment M [kNm/m]\n(+ intrados in tension)"),
                     (axV, "shear force V [kN/m]")):
        ax.set_ylabel(what)
        ax.set_xlim(0, 180)
        ax.set_xticks(np.arange(0, 181, 30))
        ax.axhline(0, color="0.6", lw=0.7)
        for a, name in ((0, "crown"), (90, "springline"), (180, "invert")):
            ax.axvline(a, color="0.85", lw=0.8, zorder=0)
        ax.grid(True, color="0.93", lw=0.6)
    for a, name in ((0, " crown"), (90, "springline"), (180, "invert ")):
        axV.text(a, 0.03, name, transform=axV.get_xaxis_transform(), ha="left" if a == 0 else
                 "right" if a == 180 else "center", va="bottom", fontsize=8, color="0.35", path_effects=HALO)
    axV.set_xlabel("angle from the crown [deg]")
    top = axN.secondary_xaxis("top", functions=(lambda d: np.radians(d) * forces.radius,
                                                lambda s: np.degrees(s / forces.radius)))
    top.set_xlabel("arc length along the lining's centreline from the crown [m]", labelpad=12)
    axN.legend(loc="best", fontsize=8)
    # extremes of the last stage, marked
    ex = forces.extremes(last)
    for key, ax, arr in (("N_max", axN, forces.N[last]), ("M_max", axM, forces.M[last]), ("M_min", axM, forces.M[last])):
        v, a = ex[key]
        ax.plot([a], [v], "o", color="k", ms=4)
        ax.annotate(f"{_nice(v)} at {a:.0f}°", (a, v), xytext=(6, -12 if key != "M_min" else 4), textcoords="offset points",
                    fontsize=8, path_effects=HALO)

    # the ring in section with the moment diagram on the tension side (+: intrados in tension, inwards)
    R = forces.radius
    t = np.radians(ang)
    x, y = R * np.sin(t), R * np.cos(t)  # crown on top, the modelled half on the right
    nx, ny = np.sin(t), np.cos(t)  # outward normal
    th = np.linspace(0, np.pi, 200)
    h = forces.thickness / 2
    axR.fill(np.concatenate([(R + h) * np.sin(th), (R - h) * np.sin(th[::-1])]),
             np.concatenate([(R + h) * np.cos(th), (R - h) * np.cos(th[::-1])]), color="0.82", lw=0,
             label=f"lining ({forces.thickness:g} m)")
    axR.plot(-R * np.sin(th), R * np.cos(th), color="0.75", lw=0.8, ls=":")
    axR.plot([0, 0], [-1.25 * R, 1.25 * R], color="0.6", lw=0.8, ls="-.")
    M = forces.M[last]
    sM = 0.3 * R / max(np.abs(M).max(), 1e-30)
    mx, my = x - sM * M * nx, y - sM * M * ny
    axR.fill(np.concatenate([x, mx[::-1]]), np.concatenate([y, my[::-1]]), color="#d62728", alpha=0.25, lw=0)
    axR.plot(mx, my, color="#d62728", lw=1.4, label=f"M on the tension side ({1 / sM:.3g} kNm/m per m)")
    for key in ("M_max", "M_min"):
        v, a = ex[key]
        i = int(np.argmin(np.abs(ang - a)))
        px, py = x[i] - sM * v * nx[i], y[i] - sM * v * ny[i]
        axR.annotate(f"M = {_nice(v)} kNm/m\n{a:.0f}° from the crown", (px, py), fontsize=8.5, color="#b22222",
                     xytext=(10 if v < 0 else -10, 0), textcoords="offset points", va="center",
                     ha="left" if v < 0 else "right", path_effects=HALO)
    for a, name in ((0, "crown"), (180, "invert")):
        axR.text(0.04 * R, (1 if a == 0 else -1) * (R + 0.12 * R), name, fontsize=8, color="0.35",
                 va="bottom" if a == 0 else "top")
    axR.set_aspect("equal")
    axR.set_xlim(-0.55 * R, 1.75 * R)
    axR.set_ylim(-1.45 * R, 1.45 * R)
    axR.set_axis_off()
    axR.legend(loc="lower left", fontsize=8, frameon=False)
    axR.set_title(f"bending moment after stage '{forces.stages[last]}'", fontsize=9.5)
    who = f"{res.name}: " if res is not None else ""
    at = "at the estimate" if res is not None else "at the case's values"
    fig.suptitle(f"{who}forces in the lining '{forces.name}' {at} (per metre of tunnel)\n"
                 f"thickness {forces.thickness:g} m, E = {forces.E / 1e6:.4g} GPa, ν = {forces.nu:g}, "
                 f"centreline radius {forces.radius:.4g} m; installed stress-free at stage "
                 f"'{forces.stages[0]}'", fontsize=10.5)
    return fig
