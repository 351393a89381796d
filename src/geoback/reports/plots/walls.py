"""The retaining walls and their supports, the figures an engineer pastes into a report:

- ``walls_figure``: each wall's deflection, bending moment and shear against depth, one line per
  construction stage (its 95 % band shaded where parameters are identified), the excavation level of
  every stage and the levels of the props and anchors marked;
- ``supports_figure``: the axial force of every prop and anchor after each stage, per metre run of
  wall, with its 95 % band and the force per prop or anchor written beside it.

Both read a ``worth.walls.WallsAndSupports`` (no model run)."""
from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from geoback.reports.plots.common import HALO, new_figure, plain
from geoback.reports.plots.lining import STAGE_COLOURS

SUPPORT_COLOUR = "0.35"
DEPTH = "depth below the ground surface [m]"


def _title_head(res) -> str:
    return f"{res.name}: " if res is not None else ""


def walls_figure(ws, res=None) -> Figure | None:
    """Deflection, bending moment and shear of every wall against depth, one row per wall."""
    if ws is None or not ws.walls:
        return None
    walls = list(ws.walls.values())
    fig = new_figure(12.5, 6.4 * len(walls) + 0.6)
    axes = fig.subplots(len(walls), 3, sharey="row", squeeze=False)
    for row, w in zip(axes, walls):
        towards = w.pit_side  # deflection towards the excavation = pit_side * ux
        face = "retained side" if w.pit_side < 0 else "excavated side"  # M + with the face at larger x in tension
        panels = ((row[0], "ux", 1e3 * towards, "deflection towards the excavation [mm]"),
                  (row[1], "M", 1.0, f"bending moment [kNm/m]\n(+ {face} in tension)"),
                  (row[2], "V", 1.0, "shear force [kN/m]"))
        for k, stage in enumerate(w.stages):
            if not np.isfinite(w.M[k]).any():
                continue
            c = STAGE_COLOURS[k % len(STAGE_COLOURS)]
            last = k == len(w.stages) - 1
            for ax, q, f, _ in panels:
                v = f * getattr(w, q)[k]
                s = getattr(w, f"{q}_std")
                if s is not None:
                    ax.fill_betweenx(w.depths, v - ws.z * abs(f) * s[k], v + ws.z * abs(f) * s[k], color=c, alpha=0.15,
                                     lw=0)
                ax.plot(v, w.depths, color=c, lw=1.8 if last else 1.2,
                        label=f"after '{stage}' (dug to {w.formation[k]:g} m)")
            for ax, *_ in panels:  # the excavation level of the stage
                ax.axhline(w.formation[k], color=c, lw=0.9, ls=(0, (5, 3)), zorder=1)
        for ax, q, f, label in panels:
            ax.axvline(0, color="0.6", lw=0.7)
            ax.set_xlabel(label)
            ax.grid(True, color="0.93", lw=0.6)
            for name, d in w.supports.items():
                ax.axhline(d, color=SUPPORT_COLOUR, lw=1.0, ls="-.", zorder=1)
        for name, d in w.supports.items():  # the supports named on the deflection panel
            s = ws.supports[name]
            row[0].annotate(f"{name} ({s.kind}, from '{s.installed}')", (0.02, d), xycoords=("axes fraction", "data"),
                            xytext=(0, 2), textcoords="offset points", fontsize=7.5, color=SUPPORT_COLOUR,
                            va="bottom", path_effects=HALO)
        k = len(w.stages) - 1  # the largest moment after the last stage, marked
        m, dm, _ = w.largest("M", k)
        if np.isfinite(m):
            row[1].plot([m], [dm], "o", color="k", ms=4)
            row[1].annotate(f"{m:.3g} kNm/m at {dm:.3g} m", (m, dm), xytext=(6, 6), textcoords="offset points",
                            fontsize=8, path_effects=HALO)
        row[0].set_ylabel(f"wall '{w.name}': {DEPTH}")
        row[0].set_ylim(w.toe + 0.02 * (w.toe - w.top), w.top - 0.02 * (w.toe - w.top))  # downwards
        row[0].legend(loc="lower left", fontsize=7.5, frameon=False,
                      title="dashed: excavation level\ndash-dot: props, anchors", title_fontsize=7.5)
    band = " (shaded: 95 % band)" if ws.banded else ""
    at = "at the estimate" if res is not None else "at the case's values"
    sizes = "; ".join(f"'{w.name}' {w.thickness:g} m thick at x = {w.x:g} m, toe at {w.toe:g} m" for w in walls)
    fig.suptitle(f"{_title_head(res)}retaining wall{'s' if len(walls) > 1 else ''} after each construction stage "
                 f"{at}{band}, per metre run\n{sizes}", fontsize=10.5)
    return fig


def supports_figure(ws, res=None) -> Figure | None:
    """Axial force of every prop and anchor after each stage (per metre run, with the 95 % band)."""
    if ws is None or not ws.supports:
        return None
    sups = list(ws.supports.values())
    stages = list(sups[0].stages)
    fig = new_figure(max(6.4, 1.3 * len(stages) + 2.5), 4.4)
    ax = fig.subplots()
    x = np.arange(len(stages))
    width = 0.8 / len(sups)
    for j, s in enumerate(sups):
        c = STAGE_COLOURS[j % len(STAGE_COLOURS)]
        xs = x - 0.4 + width * (j + 0.5)
        on = np.isfinite(s.force)
        err = None
        if s.std is not None:
            err = ws.z * np.where(on, s.std, 0.0)[on]
        word = "compression" if s.kind == "prop" else "tension"
        ax.bar(xs[on], s.force[on], width * 0.9, yerr=err, capsize=3, color=c, alpha=0.85,
               label=f"{s.name}: {s.kind} at {s.depth:g} m on '{s.wall}' ({word} +)"
                     + (f", every {s.spacing:g} m" if s.spacing is not None else ""))
        tops = s.force[on] + (err if err is not None else 0.0)
        for xi, f, top in zip(xs[on], s.force[on], tops):
            text = plain(f) + (f"\n({plain(s.spacing * f)} kN)" if s.spacing is not None else "")
            ax.annotate(text, (xi, max(top, 0.0)), xytext=(0, 3), textcoords="offset points", ha="center", va="bottom",
                        fontsize=7, path_effects=HALO)
        for xi in xs[~on]:
            ax.text(xi, 0, "not\ninstalled", ha="center", va="bottom", fontsize=6.5, color="0.5")
    ax.set_xticks(x, [f"after '{st}'" for st in stages])
    ax.set_xlim(-0.6, len(stages) - 0.4)
    ax.set_xlabel("construction stage")
    ax.set_ylabel("axial force per metre run of wall [kN/m]")
    ax.axhline(0, color="0.6", lw=0.7)
    ax.margins(y=0.18)
    ax.grid(True, axis="y", color="0.93", lw=0.6)
    ax.legend(loc="upper left", fontsize=8, frameon=False)
    band = "; error bars: 95 % band" if ws.banded else ""
    at = "at the estimate" if res is not None else "at the case's values"
    fig.suptitle(f"{_title_head(res)}forces in the props and anchors after each stage {at}\n"
                 f"per metre run (in brackets: per prop or anchor where a spacing is given){band}", fontsize=10.5)
    return fig
