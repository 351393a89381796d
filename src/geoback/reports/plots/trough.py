"""The settlement trough and the buildings' damage, as an engineer pastes them into a report:

- ``trough_figure``: per construction stage, the surface settlements read (± 1.96 σ) with the Gaussian
  trough fitted to them and its 95 % band (from C_x), the model's surface settlement at the estimate
  and the Gaussian trough fitted to it with its 95 % band (from C_p); settlement downwards, in mm;
- ``damage_figure``: per building, the building drawn over the greenfield settlement along it (every
  stage assessed, its sagging and hogging parts marked) and the probability of each damage category.

Both read a ``worth.trough.Troughs`` / ``worth.damage.Damage`` (no model run)."""
from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from geoback.reports.plots.common import new_figure
from geoback.reports.plots.lining import STAGE_COLOURS

MEASURED = "#2ca02c"
MODEL = "#1f77b4"
CATEGORY_COLOURS = ("#2ca02c", "#a6d96a", "#fee08b", "#fdae61", "#d73027")


def _head(res) -> str:
    return f"{res.name}: " if res is not None else ""


def trough_figure(tr, res=None) -> Figure | None:
    """One panel per stage with a trough: readings, both fitted troughs and their bands (mm against m)."""
    if tr is None or not tr:
        return None
    stages = [s for s in tr.stages if s in tr.measured or s in tr.predicted]
    n = len(stages)
    cols = min(n, 2)
    rows = math.ceil(n / cols)
    fig = new_figure(6.2 * cols, 3.9 * rows + 0.5)
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    half = any(t.half for t in list(tr.measured.values()) + list(tr.predicted.values()))
    for ax, stage in zip(axes, stages):
        notes = []
        m, p = tr.measured.get(stage), tr.predicted.get(stage)
        if p is not None:
            ax.plot(p.x, 1e3 * p.s, color="0.55", lw=1.0, ls=(0, (4, 2)), label="model's surface settlement")
            _fitted(ax, p, tr.z, MODEL, "model's", notes)
        if m is not None:
            ax.errorbar(m.x, 1e3 * m.s, yerr=1e3 * tr.z_measured * m.s_std, fmt="o", ms=4.5, color=MEASURED,
                        ecolor=MEASURED, elinewidth=1.0, capsize=2.5, label="measured (± 1.96 σ)", zorder=5)
            _fitted(ax, m, tr.z_measured, MEASURED, "measured", notes)
        ax.axhline(0, color="0.6", lw=0.7)
        ax.invert_yaxis()  # settlement downwards
        ax.set_title(f"after stage '{stage}'")
        ax.set_xlabel("distance from the tunnel axis [m]" if half else "x, horizontal position [m]")
        ax.set_ylabel("settlement [mm]")
        ax.grid(True, color="0.93", lw=0.6)
        ax.legend(loc="lower right", frameon=False)
        if notes:
            ax.text(0.02, 0.03, "\n".join(_wrap(t) for t in notes), transform=ax.transAxes, fontsize=7.5,
                    va="bottom", color="0.25")
    for ax in axes[n:]:
        ax.set_visible(False)
    fig.suptitle(f"{_head(res)}surface settlement trough per stage (Gaussian fits, 95 % bands)")
    return fig


def _fitted(ax, t, z: float, colour: str, who: str, notes: list) -> None:
    """A fitted trough with its 95 % band, or why it is not determined (into `notes`)."""
    if not t.determined:
        notes.append(f"{who} trough not determined: {t.reason}")
        return
    lo, hi = t.curve - z * t.curve_std, t.curve + z * t.curve_std
    ax.fill_between(t.curve_x, 1e3 * lo, 1e3 * hi, color=colour, alpha=0.2 if who == "model's" else 0.15, lw=0)
    ax.plot(t.curve_x, 1e3 * t.curve, color=colour, lw=1.8 if who == "model's" else 1.5,
            label=f"{who} trough: V_L {t.values['V_L']:.2f} %, i {t.values['i']:.1f} m (95 % band)")


def _wrap(text: str, width: int = 70) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(text, width))


def damage_figure(dm, res=None) -> Figure | None:
    """Per building: the building over the greenfield settlement along it, and the category probabilities."""
    from geoback.worth.damage import CATEGORIES

    if dm is None or not dm.buildings:
        return None
    bs = list(dm.buildings.values())
    fig = new_figure(11.5, 4.4 * len(bs) + 0.5)
    grid = fig.add_gridspec(2 * len(bs), 2, height_ratios=[1, 2.4] * len(bs), width_ratios=[1.7, 1])
    for row, b in enumerate(bs):
        top = fig.add_subplot(grid[2 * row, 0])
        prof = fig.add_subplot(grid[2 * row + 1, 0], sharex=top)
        bars = fig.add_subplot(grid[2 * row:2 * row + 2, 1])
        stages = list(b.stages)
        last = b.stages[stages[-1]]
        top.add_patch(Rectangle((b.x_start, 0), b.length, b.height, facecolor="#e8dcc8", edgecolor="0.3", lw=1.0))
        for p in last.parts:
            top.axvspan(p.x_a, p.x_b, ymax=0.08, color="#d62728" if p.mode == "hogging" else "#1f77b4", alpha=0.6)
            top.text(0.5 * (p.x_a + p.x_b), 0.5 * b.height, p.mode, ha="center", va="center", fontsize=8)
        top.set_ylim(-0.1 * b.height, 1.25 * b.height)
        top.set_ylabel("height [m]")
        top.set_title(f"building '{b.name}': {b.height:g} m high, L = {b.length:g} m"
                      + (f", foundation {b.foundation_depth:g} m deep" if b.foundation_depth else ""))
        top.tick_params(labelbottom=False)
        for k, stage in enumerate(stages):
            s = b.stages[stage]
            c = STAGE_COLOURS[k % len(STAGE_COLOURS)]
            prof.plot(s.x, -1e3 * s.uy, color=c, lw=1.8 if k == len(stages) - 1 else 1.1,
                      label=f"after '{stage}': category {CATEGORIES[s.category]}")
        for p in last.parts[1:]:
            prof.axvline(p.x_a, color="0.4", lw=0.8, ls=":")
        prof.invert_yaxis()
        prof.set_xlabel("x, horizontal position [m]")
        prof.set_ylabel("greenfield settlement [mm]")
        prof.grid(True, color="0.93", lw=0.6)
        prof.legend(loc="best", frameon=False)
        if last.probabilities is not None:
            bars.bar(range(len(CATEGORIES)), 100 * last.probabilities, color=CATEGORY_COLOURS)
            bars.set_ylim(0, 105)
            for k, v in enumerate(last.probabilities):
                bars.text(k, 100 * v + 1.5, f"{100 * v:.0f} %", ha="center", fontsize=8)
        else:
            bars.text(0.5, 0.5, "no probabilities\n(no parameter uncertainty)", ha="center", va="center",
                      transform=bars.transAxes)
        bars.set_xticks(range(len(CATEGORIES)), [_wrap(c, 9) for c in CATEGORIES], fontsize=7.5)
        bars.set_ylabel("probability [%]")
        bars.set_title(f"damage category after '{stages[-1]}'")
    fig.suptitle(f"{_head(res)}building damage, greenfield assessment (Burland 1995)")
    return fig
