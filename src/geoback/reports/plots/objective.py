"""Objective function over the two most correlated parameters with the Gauss-Newton and
Levenberg-Marquardt paths and the SVD directions at the minimum (paper Fig. 2)."""
from __future__ import annotations

import matplotlib
import numpy as np
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from geoback.reports.plots.common import HALO, METHOD_NAMES, METHOD_STYLE, accepted_steps, axis_label, display, new_figure


def _paths(res, exploration) -> list[tuple]:
    fits = [res.fit] + ([exploration.other] if exploration.other is not None else [])
    return [(f.method, accepted_steps(f.history), f.history) for f in fits]


def objective_contours_figure(res, exploration) -> Figure:
    """J over the two most correlated parameters with both iteration paths (paper Fig. 2)."""
    slc = exploration.slice
    params, f, rel = res.parameters, res.fit, res.reliability
    fig = new_figure(7.6, 6.8)
    ax = fig.add_subplot()
    paths = _paths(res, exploration)
    if slc.j is None:
        return _objective_1d(fig, ax, res, slc, paths)
    i, j = slc.i, slc.j
    p_hat = f.p
    fi, _ = display(params.names[i], params.units[i], p_hat[i])
    fj, _ = display(params.names[j], params.units[j], p_hat[j])
    a, b, Jg = slc.a, slc.b, slc.J
    A, B = np.meshgrid(a * fi, b * fj)
    good = np.isfinite(Jg) & (Jg > 0)
    jmin_grid = np.nanmin(np.where(good, Jg, np.nan))
    jmax = np.nanmax(np.where(good, Jg, np.nan))
    low = max(jmin_grid, jmax * 1e-6, 1e-300)
    levels = np.logspace(np.log10(low), np.log10(jmax), 16)
    Jc = np.clip(np.where(good, Jg, np.nan), low, jmax)
    cs = ax.contourf(A, B, Jc, levels=levels, norm=LogNorm(low, jmax), cmap="viridis_r", extend="neither")
    ax.contour(A, B, Jc, levels=levels, colors="k", linewidths=0.45, alpha=0.45)
    cb = fig.colorbar(cs, ax=ax, shrink=0.92, pad=0.02)
    cb.set_label("objective J = ‖L⁻¹(x* − x(p))‖²  [-]" if not slc.linearised else
                 "objective of the linearised model J* + Δpᵀ A′ᵀA′ Δp  [-]")
    cb.ax.yaxis.set_major_locator(matplotlib.ticker.LogLocator(numticks=8))

    # iteration paths (accepted steps; rejected trial points as small crosses)
    for method, acc, hist in paths:
        st = METHOD_STYLE.get(method, METHOD_STYLE["lm"])
        xy = np.array([h.p[[i, j]] for h in acc]) * [fi, fj]
        ax.plot(xy[:, 0], xy[:, 1], color=st["color"], ls=st["ls"], lw=1.8, marker=st["marker"], ms=5.5,
                mec="white", mew=0.8, zorder=4,
                label=f"{METHOD_NAMES.get(method, method)} ({len(acc) - 1} iterations)")
        rej = np.array([h.p[[i, j]] for h in hist if not h.accepted]).reshape(-1, 2) * [fi, fj]
        inside = ((rej[:, 0] >= a[0] * fi) & (rej[:, 0] <= a[-1] * fi) & (rej[:, 1] >= b[0] * fj)
                  & (rej[:, 1] <= b[-1] * fj))
        if inside.any():
            ax.plot(rej[inside, 0], rej[inside, 1], ls="none", marker="x", color=st["color"], ms=5, zorder=4)
        for k, (x_, y_) in enumerate(xy[1:4], start=1):  # number the first steps
            ax.annotate(str(k), (x_, y_), xytext=(6, -11 if method == "gn" else 5), textcoords="offset points",
                        fontsize=8, color=st["color"], fontweight="bold", zorder=5, path_effects=HALO)
    p0 = paths[0][1][0].p[[i, j]] * [fi, fj]
    ax.plot(*p0, marker="*", ms=15, color="white", mec="k", mew=1.0, ls="none", zorder=6, label="start p₀")
    ph = p_hat[[i, j]] * [fi, fj]
    ax.plot(*ph, marker="P", ms=11, color="#ff7f0e", mec="k", mew=1.0, ls="none", zorder=6,
            label="estimate p̂")
    svd_handles = _svd_arrows(ax, slc, p_hat, (fi, fj), ph)
    ax.set_xlim(a[0] * fi, a[-1] * fi)
    ax.set_ylim(b[0] * fj, b[-1] * fj)
    ax.set_xlabel(axis_label(params, i, p_hat[i]))
    ax.set_ylabel(axis_label(params, j, p_hat[j]))
    held = [nm for k, nm in enumerate(params.names) if k not in (i, j)]
    lines = [f"Objective function J({params.names[i]}, {params.names[j]}) and iteration paths",
             f"{res.weighting} weighting, correlation {rel.correlation[i, j]:+.2f}", *map_words(slc)]
    if held:
        lines.append(f"slice with {', '.join(held)} held at the estimate; paths projected onto it")
    ax.set_title("\n".join(lines), fontsize=10)
    handles, _ = ax.get_legend_handles_labels()
    ax.legend(handles=handles + svd_handles, loc="upper center", bbox_to_anchor=(0.5, -0.09), ncols=2,
              frameon=False)  # below the map, never over it
    return fig


def map_words(slc) -> list[str]:
    """What the map shows, in the figure's words (title lines)."""
    if not slc.linearised:
        return [f"J computed by the model on a {len(slc.a)}×{len(slc.b)} grid" if slc.b is not None else
                "J computed by the model"]
    if slc.requested:
        return ["J of the model linearised at the estimate (as asked)"]
    return ["J of the model linearised at the estimate: the model itself would need a new solution at every",
            "point of the map (geoback run --plots --objective-map model draws that)"]


def _svd_arrows(ax, slc, p_hat, factors, ph) -> list:
    """SVD directions at the minimum (eqns 44-49): V holds relative changes dp/p, so the plot's
    (dp_i, dp_j) = (v_i p_i, v_j p_j). With more than two parameters the directions are those of
    the SVD of the slice's two whitened sensitivity columns."""
    i, j = slc.i, slc.j
    fi, fj = factors
    a, b = slc.a, slc.b
    V, sv = slc.directions, slc.singular_values
    vlabel = "SVD direction at p̂" if slc.whole_svd else "SVD direction of this slice at p̂"
    xr, yr = (a[-1] - a[0]) * fi, (b[-1] - b[0]) * fj
    handles = []
    for k in range(min(2, V.shape[1])):
        v = V[:, k]
        d = np.array([v[i] * p_hat[i] * fi, v[j] * p_hat[j] * fj])
        dn = np.hypot(d[0] / xr, d[1] / yr)
        if not np.isfinite(dn) or dn == 0:
            continue
        d = d / dn * 0.18  # 18 % of the frame, direction preserved in data coordinates
        # the sign of a singular vector is arbitrary: point into the frame, towards its centre
        centre = np.array([(a[0] + a[-1]) / 2 * fi, (b[0] + b[-1]) / 2 * fj])
        if np.dot(d / [xr, yr], (centre - ph) / [xr, yr]) < 0:
            d = -d
        ax.annotate("", xy=(ph[0] + d[0], ph[1] + d[1]), xytext=(ph[0], ph[1]), zorder=5,
                    arrowprops=dict(arrowstyle="-|>", lw=2.0, color="k" if k == 0 else "0.35",
                                    shrinkA=0, shrinkB=0, mutation_scale=14))
        u_ = d / [xr, yr] / np.hypot(*(d / [xr, yr]))  # direction on screen (frame fractions)
        ax.annotate(f"V{k + 1}", xy=(ph[0] + d[0], ph[1] + d[1]), fontweight="bold",
                    xytext=(7 * u_[0], 7 * u_[1]), textcoords="offset points", fontsize=9, zorder=6,
                    annotation_clip=False, ha="left" if u_[0] > 0.3 else "right" if u_[0] < -0.3 else "center",
                    va="bottom" if u_[1] > 0.3 else "top" if u_[1] < -0.3 else "center",
                    bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.75))
        handles.append(Line2D([], [], color="k" if k == 0 else "0.35", lw=2, marker=r"$\rightarrow$", ms=10,
                              ls="none", label=f"V{k + 1}: {vlabel}, s{k + 1} = {sv[k]:.3g}"))
    return handles


def _objective_1d(fig, ax, res, slc, paths) -> Figure:
    params, f = res.parameters, res.fit
    fi, _ = display(params.names[0], params.units[0], f.p[0])
    ax.semilogy(slc.a * fi, slc.J, color="0.3", lw=1.5,
                label="J" if not slc.linearised else "J of the model linearised at the estimate")
    for method, acc, _ in paths:
        st = METHOD_STYLE.get(method, METHOD_STYLE["lm"])
        ax.plot([h.p[0] * fi for h in acc], [max(h.J, 1e-300) for h in acc], color=st["color"], ls=st["ls"],
                marker=st["marker"], label=f"{METHOD_NAMES.get(method, method)} ({len(acc) - 1} iterations)")
    ax.plot(paths[0][1][0].p[0] * fi, max(paths[0][1][0].J, 1e-300), marker="*", ms=15, color="white", mec="k",
            ls="none", zorder=6, label="start p₀")
    ax.plot(f.p[0] * fi, max(f.J, 1e-300), marker="P", ms=11, color="#ff7f0e", mec="k", ls="none", zorder=6,
            label="estimate p̂")
    ax.set_xlabel(axis_label(params, 0, f.p[0]))
    ax.set_ylabel("objective J [-]")
    ax.set_title("\n".join([f"Objective function J({params.names[0]}) and iteration paths", *map_words(slc)]))
    ax.legend()
    return fig
