"""J and every parameter relative to its final value, per iteration, for both methods (paper
Figs. 3-4)."""
from __future__ import annotations

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import MaxNLocator

from geoback.inference.explore import other_method
from geoback.reports.plots.common import METHOD_NAMES, METHOD_STYLE, accepted_steps, new_figure, value_text


def convergence_figure(res, exploration) -> Figure:
    """J and every parameter / its final value, per iteration, for both methods (Figs. 3-4)."""
    params = res.parameters
    other = exploration.other if exploration is not None else None
    fig = new_figure(11.0, 4.3)
    axJ, axP = fig.subplots(1, 2)
    fits = [res.fit] + ([other] if other is not None else [])
    colours = colormaps["Dark2"]  # parameters (methods keep their blue / red)
    for fit in fits:
        st = METHOD_STYLE.get(fit.method, METHOD_STYLE["lm"])
        acc = accepted_steps(fit.history)
        k = np.array([h.k for h in acc])
        Jv = np.array([max(h.J, 1e-300) for h in acc])
        name = METHOD_NAMES.get(fit.method, fit.method)
        axJ.semilogy(k, Jv, color=st["color"], ls=st["ls"], marker=st["marker"], ms=5, lw=1.6,
                     label=f"{name}: J = {fit.J:.3g}")
        rej = [(h.k, h.J) for h in fit.history if not h.accepted and np.isfinite(h.J)]  # not: no solution there
        if rej:
            rk, rJ = np.array(rej).T
            axJ.plot(rk, np.maximum(rJ, 1e-300), ls="none", marker="x", color=st["color"], ms=5)
        final = fit.p
        for m in range(params.n):
            vals = np.array([h.p[m] for h in acc])
            y = vals / final[m] if final[m] != 0 else vals
            # later parameters drawn thinner on top, so coinciding curves stay visible
            axP.plot(k, y, color=colours(m % 8), ls=st["ls"], marker=st["marker"], ms=max(6.5 - 1.5 * m, 3),
                     lw=max(2.6 - 0.7 * m, 0.9), mfc="white" if fit is not fits[0] else colours(m % 8))
    if any(not h.accepted for fit in fits for h in fit.history):
        axJ.plot([], [], ls="none", marker="x", color="0.4", label="rejected trial step")
    axJ.set_xlabel("iteration k [-]")
    axJ.set_ylabel("objective J [-]  (log scale)")
    axJ.set_title("Objective function per iteration")
    axJ.legend(framealpha=0.9)
    axP.axhline(1.0, color="0.6", lw=0.8, zorder=0)
    axP.set_xlabel("iteration k [-]")
    axP.set_ylabel("parameter / final estimate [-]")
    axP.set_title("Parameters per iteration")
    handles = [Line2D([], [], color=colours(m % 8), lw=2,
                      label=f"{params.names[m]} (p̂ = {value_text(params, m, res.fit.p[m])})")
               for m in range(params.n)]
    handles += [Line2D([], [], color="0.3", **{k: v for k, v in METHOD_STYLE.get(fit.method, METHOD_STYLE["lm"]).items()
                                               if k != "color"}, label=METHOD_NAMES.get(fit.method, fit.method))
                for fit in fits]
    axP.legend(handles=handles, framealpha=0.9, loc="best")
    for ax in (axJ, axP):
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(True, which="major", color="0.9", lw=0.6)
    title = f"Convergence ({res.weighting} weighting)"
    note = getattr(exploration, "other_note", "") if exploration is not None else ""
    if other is None and note:
        title += f"\n{METHOD_NAMES.get(other_method(res.fit.method), 'the other method')} {note}"
    fig.suptitle(title, fontsize=11)
    return fig

