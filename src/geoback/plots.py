"""Figures of a run (`geoback run --plots`), after the paper's Figs. 2-5 and 8.

- ``objective_contours``: J over the two most correlated parameters with the Gauss-Newton and
  Levenberg-Marquardt paths and the SVD directions V1, V2 at the minimum (Fig. 2);
- ``convergence``: J and the parameters (relative to their final values) per iteration (Figs. 3-4);
- ``information_density``: rows of Q for the readings of highest leverage, and Q itself (Figs. 5, 8);
- ``instruments``: measured and computed readings along every instrument with +-2 sigma bands;
- ``field``: the deformed mesh coloured by the displacement magnitude, with the instruments.

Figures are built as :class:`matplotlib.figure.Figure` objects without pyplot (no global state,
headless); :func:`build_figures` returns them, :func:`save_figures` writes them and
:func:`plot_run` does both. Building the figures evaluates the model (a grid of J values, the
other method's fit, the field): the problem's counters are restored afterwards so that the
run's summary reports the identification only.
"""
from __future__ import annotations

import copy
import io
import sys
import textwrap
from pathlib import Path

import matplotlib

if "matplotlib.pyplot" not in sys.modules:  # never switch the backend of an interactive session
    matplotlib.use("Agg")

import numpy as np  # noqa: E402
from matplotlib import colormaps  # noqa: E402
from matplotlib import patheffects  # noqa: E402
from matplotlib.colors import LogNorm, TwoSlopeNorm  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402
from matplotlib.transforms import blended_transform_factory  # noqa: E402
from matplotlib.tri import Triangulation  # noqa: E402

from .outputs import write_atomic  # noqa: E402

FIGURES = ("objective_contours", "convergence", "information_density", "instruments", "field")
FORMATS = ("png", "svg")
DPI = 150
GRID = 40  # contour grid points per axis when one factorisation serves the whole grid
GRID_CAPPED = 25  # ... when every grid point needs its own factorisation (nu or several layers vary)
HALO = [patheffects.withStroke(linewidth=2.5, foreground="white")]
FIELD_TARGET = 0.35  # the largest displacement is drawn as about this fraction of the tunnel radius
# (rounded down to a magnification of 1, 2 or 5 x 10^k)

METHOD_NAMES = {"lm": "Levenberg-Marquardt", "lm-scaled": "Levenberg-Marquardt (scaled)", "gn": "Gauss-Newton"}
METHOD_STYLE = {"lm": dict(color="#1f77b4", marker="o", ls="-"),
                "lm-scaled": dict(color="#1f77b4", marker="o", ls="-"),
                "gn": dict(color="#d62728", marker="s", ls="--")}
RC = {"font.size": 9.5, "axes.titlesize": 10.5, "axes.labelsize": 9.5, "legend.fontsize": 8.5,
      "xtick.labelsize": 8.5, "ytick.labelsize": 8.5, "axes.grid": False, "figure.dpi": DPI,
      "svg.hashsalt": "geoback", "savefig.bbox": "tight", "savefig.pad_inches": 0.08}


# ---------------------------------------------------------------------------------------- helpers
def _other_method(method: str) -> str:
    return "lm" if method == "gn" else "gn"


def _display(name: str, unit: str, value: float) -> tuple[float, str]:
    """Factor and unit to show a parameter with (kPa moduli in MPa)."""
    if unit == "kPa" and abs(value) >= 1e3:
        return 1e-3, "MPa"
    if unit == "kPa/m" and abs(value) >= 1e3:
        return 1e-3, "MPa/m"
    return 1.0, unit or "-"


def _axis_label(params, i: int, value: float) -> str:
    f, unit = _display(params.names[i], params.units[i], value)
    return f"{params.names[i]} [{unit}]"


def _short(labels, i: int, multi: set[str]) -> str:
    lab = labels[i]
    s = f"{lab.instrument}:{lab.station}"
    return s + f" {lab.component}" if lab.instrument in multi else s


def _multi_component(labels) -> set[str]:
    comps: dict[str, set[str]] = {}
    for lab in labels:
        comps.setdefault(lab.instrument, set()).add(lab.component)
    return {k for k, v in comps.items() if len(v) > 1}


def _accepted(history) -> list:
    """One entry per iteration: the accepted point (iteration 0 is the start)."""
    out = {}
    for h in history:
        if h.accepted:
            out[h.k] = h
    return [out[k] for k in sorted(out)]


def _J(res, p: np.ndarray) -> float:
    """Objective of eqn (6), whitened: ||L^-1 (x* - x(p))||^2 plus the prior terms."""
    obj = res.objective
    r = obj.whiten(obj.measured - res.problem.predict(p))
    rp, _ = obj.prior_rows(p)
    return float(r @ r + rp @ rp)


def _J_many(res, P: np.ndarray) -> np.ndarray:
    """J at every row of P. Cheap when only moduli and K0 vary: the factorisation is reused
    (eqn 41) and every load lies in the span of earlier ones (solver.Factorisation)."""
    P = np.atleast_2d(P)
    out = np.full(len(P), np.nan)
    for k, p in enumerate(P):  # one forward run per point
        try:
            out[k] = _J(res, p)
        except Exception:  # noqa: BLE001 - a failed forward run leaves a hole in the grid
            pass
    return out


def _nice_factor(x: float) -> float:
    """Largest of 1, 2, 5 x 10^k not above x (at least 1)."""
    if not np.isfinite(x) or x <= 1:
        return 1.0
    k = np.floor(np.log10(x))
    for m in (5, 2, 1):
        if m * 10 ** k <= x:
            return float(m * 10 ** k)
    return float(10 ** k)


def _new_figure(w: float, h: float) -> Figure:
    return Figure(figsize=(w, h), dpi=DPI, layout="constrained")


# ------------------------------------------------------------------------------- the figures
def objective_contours_figure(res, other=None, grid: int | None = None) -> Figure:
    """J over the two most correlated parameters with both iteration paths (paper Fig. 2)."""
    pr, f, rel = res.problem, res.fit, res.reliability
    params = pr.params
    n = params.n
    fig = _new_figure(7.6, 6.0)
    ax = fig.add_subplot()
    paths = [(f.method, _accepted(f.history), f.history)]
    if other is not None:
        paths.append((other.method, _accepted(other.history), other.history))
    p_hat = f.p
    if n == 1:
        return _objective_1d(fig, ax, res, paths)
    if n == 2:
        i, j = 0, 1
    else:
        C = np.abs(np.nan_to_num(rel.correlation, nan=0.0))
        np.fill_diagonal(C, -1)
        i, j = np.unravel_index(np.argmax(C), C.shape)
        i, j = int(min(i, j)), int(max(i, j))
    fi, _ = _display(params.names[i], params.units[i], p_hat[i])
    fj, _ = _display(params.names[j], params.units[j], p_hat[j])

    # grid range: every accepted point of both paths and the estimate, padded, inside the bounds
    pts = np.array([h.p[[i, j]] for _, acc, _ in paths for h in acc] + [p_hat[[i, j]]])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    span = np.maximum(hi - lo, 0.1 * np.maximum(np.abs(p_hat[[i, j]]), 1e-12))
    lo, hi = lo - 0.12 * span, hi + 0.12 * span
    lo = np.minimum(lo, p_hat[[i, j]] - 0.3 * span)  # room around the minimum for V1, V2
    hi = np.maximum(hi, p_hat[[i, j]] + 0.3 * span)
    blo, bhi = params.lower[[i, j]], params.upper[[i, j]]
    with np.errstate(invalid="ignore"):
        lo = np.where(np.isfinite(blo), np.maximum(lo, blo + 1e-9 * np.abs(blo)), lo)
        hi = np.where(np.isfinite(bhi), np.minimum(hi, bhi - 1e-9 * np.abs(bhi)), hi)

    def at(a, b):
        p = p_hat.copy()
        p[i], p[j] = a, b
        return p

    # probe: does each new point need its own factorisation (nu or several moduli vary)?
    before = pr.counters.factorisations
    _J(res, at(lo[0], lo[1]))
    _J(res, at(hi[0], hi[1]))
    refactorises = pr.counters.factorisations - before >= 2
    ng = grid or (GRID_CAPPED if refactorises else GRID)
    a = np.linspace(lo[0], hi[0], ng)
    b = np.linspace(lo[1], hi[1], ng)
    AA, BB = np.meshgrid(a, b)
    grid_p = np.repeat(p_hat[None], ng * ng, axis=0)
    grid_p[:, i], grid_p[:, j] = AA.ravel(), BB.ravel()
    Jg = _J_many(res, grid_p).reshape(ng, ng)
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
    cb.set_label("objective J = ‖L⁻¹(x* − x(p))‖²  [-]")
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

    # SVD directions at the minimum (eqns 44-49): V holds relative changes dp/p, so the plot's
    # (dp_i, dp_j) = (v_i p_i, v_j p_j). With more than two parameters the directions of the
    # plotted slice are those of the SVD of the two plotted columns of the whitened sensitivity.
    if n == 2:
        V, sv = rel.directions, rel.singular_values
        vlabel = "SVD direction at p̂"
    else:
        As = res.objective.whiten(f.A[:, [i, j]]) * np.where(p_hat[[i, j]] != 0, np.abs(p_hat[[i, j]]), 1.0)
        _, sv, Vt = np.linalg.svd(As, full_matrices=False)
        V = np.zeros((n, 2))
        V[[i, j], :] = Vt.T
        vlabel = "SVD direction of this slice at p̂"
    xr, yr = (a[-1] - a[0]) * fi, (b[-1] - b[0]) * fj
    svd_handles = []
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
        svd_handles.append(Line2D([], [], color="k" if k == 0 else "0.35", lw=2, marker=r"$\rightarrow$", ms=10,
                                  ls="none", label=f"V{k + 1}: {vlabel}, s{k + 1} = {sv[k]:.3g}"))
    ax.set_xlim(a[0] * fi, a[-1] * fi)
    ax.set_ylim(b[0] * fj, b[-1] * fj)
    ax.set_xlabel(_axis_label(params, i, p_hat[i]))
    ax.set_ylabel(_axis_label(params, j, p_hat[j]))
    held = [nm for k, nm in enumerate(params.names) if k not in (i, j)]
    lines = [f"Objective function J({params.names[i]}, {params.names[j]}) and iteration paths",
             f"{res.objective.weighting} weighting, correlation {rel.correlation[i, j]:+.2f}, grid {ng}×{ng}"
             + (" (capped: every grid point refactorises the stiffness)" if refactorises else "")]
    if held:
        lines.append(f"slice with {', '.join(held)} held at the estimate; paths projected onto it")
    ax.set_title("\n".join(lines), fontsize=10)
    handles, _ = ax.get_legend_handles_labels()
    ax.legend(handles=handles + svd_handles, loc="lower right", framealpha=0.9)
    return fig


def _objective_1d(fig, ax, res, paths) -> Figure:
    pr, f = res.problem, res.fit
    params = pr.params
    fi, _ = _display(params.names[0], params.units[0], f.p[0])
    pts = np.array([h.p[0] for _, acc, _ in paths for h in acc] + [f.p[0]])
    span = max(pts.max() - pts.min(), 0.1 * max(abs(f.p[0]), 1e-12))
    lo, hi = pts.min() - 0.12 * span, pts.max() + 0.12 * span
    if np.isfinite(params.lower[0]):
        lo = max(lo, params.lower[0])
    if np.isfinite(params.upper[0]):
        hi = min(hi, params.upper[0])
    grid = np.union1d(np.linspace(lo, hi, 120), pts[(pts >= lo) & (pts <= hi)])
    Jg = _J_many(res, grid[:, None])
    ax.semilogy(grid * fi, Jg, color="0.3", lw=1.5, label="J")
    for method, acc, _ in paths:
        st = METHOD_STYLE.get(method, METHOD_STYLE["lm"])
        ax.plot([h.p[0] * fi for h in acc], [max(h.J, 1e-300) for h in acc], color=st["color"], ls=st["ls"],
                marker=st["marker"], label=f"{METHOD_NAMES.get(method, method)} ({len(acc) - 1} iterations)")
    ax.plot(paths[0][1][0].p[0] * fi, max(paths[0][1][0].J, 1e-300), marker="*", ms=15, color="white", mec="k",
            ls="none", zorder=6, label="start p₀")
    ax.plot(f.p[0] * fi, max(f.J, 1e-300), marker="P", ms=11, color="#ff7f0e", mec="k", ls="none", zorder=6,
            label="estimate p̂")
    ax.set_xlabel(_axis_label(params, 0, f.p[0]))
    ax.set_ylabel("objective J [-]")
    ax.set_title(f"Objective function J({params.names[0]}) and iteration paths")
    ax.legend()
    return fig


def convergence_figure(res, other=None) -> Figure:
    """J and every parameter / its final value, per iteration, for both methods (Figs. 3-4)."""
    params = res.problem.params
    fig = _new_figure(11.0, 4.3)
    axJ, axP = fig.subplots(1, 2)
    fits = [res.fit] + ([other] if other is not None else [])
    colours = colormaps["Dark2"]  # parameters (methods keep their blue / red)
    for fit in fits:
        st = METHOD_STYLE.get(fit.method, METHOD_STYLE["lm"])
        acc = _accepted(fit.history)
        k = np.array([h.k for h in acc])
        Jv = np.array([max(h.J, 1e-300) for h in acc])
        name = METHOD_NAMES.get(fit.method, fit.method)
        axJ.semilogy(k, Jv, color=st["color"], ls=st["ls"], marker=st["marker"], ms=5, lw=1.6,
                     label=f"{name}: J = {fit.J:.3g}")
        rej = [(h.k, h.J) for h in fit.history if not h.accepted]
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
                      label=f"{params.names[m]} (p̂ = {_value_text(params, m, res.fit.p[m])})")
               for m in range(params.n)]
    handles += [Line2D([], [], color="0.3", **{k: v for k, v in METHOD_STYLE.get(fit.method, METHOD_STYLE["lm"]).items()
                                               if k != "color"}, label=METHOD_NAMES.get(fit.method, fit.method))
                for fit in fits]
    axP.legend(handles=handles, framealpha=0.9, loc="best")
    for ax in (axJ, axP):
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(True, which="major", color="0.9", lw=0.6)
    fig.suptitle(f"Convergence ({res.objective.weighting} weighting)", fontsize=11)
    return fig


def information_density_figure(res, top: int = 3) -> Figure:
    """Rows of Q for the readings of highest leverage (paper Figs. 5, 8) and Q as a heat map."""
    pr, rel = res.problem, res.reliability
    labels = pr.obs.labels
    Q = rel.information_density
    m = len(labels)
    multi = _multi_component(labels)
    short = [_short(labels, i, multi) for i in range(m)]
    instruments = list(dict.fromkeys(lab.instrument for lab in labels))
    colours = colormaps["tab10"]
    inst_colour = {name: colours(k % 10) for k, name in enumerate(instruments)}
    picks = list(np.argsort(-rel.leverage, kind="stable")[:min(top, m)])
    fig = _new_figure(12.5, 2.0 + 1.9 * len(picks))
    gs = fig.add_gridspec(len(picks), 2, width_ratios=[1.45, 1.0])
    idx = np.arange(1, m + 1)
    show_ticks = m <= 40
    vmax = max(np.nanmax(np.abs(Q)), 1e-12)
    for r, i in enumerate(picks):
        ax = fig.add_subplot(gs[r, 0])
        cols = [inst_colour[lab.instrument] for lab in labels]
        bars = ax.bar(idx, Q[i], color=cols, edgecolor="none", width=0.75)
        bars[i].set_edgecolor("k")
        bars[i].set_linewidth(1.5)
        ax.axhline(0, color="0.3", lw=0.7)
        ax.set_ylim(min(-0.05 * vmax, 1.15 * Q[i].min()), 1.18 * max(Q[i].max(), 0.05 * vmax))
        ax.set_xlim(0.3, m + 0.7)
        ax.set_ylabel(f"Q[{short[i]}, j] [-]")
        ax.set_title(f"Information density: row of reading {short[i]} "
                     f"({labels[i].kind}, leverage Q_ii = {rel.leverage[i]:.3f})", loc="left", fontsize=9.5)
        if show_ticks:
            ax.set_xticks(idx)
            ax.set_xticklabels(short if r == len(picks) - 1 else [""] * m, rotation=90 if m > 12 else 45,
                               ha="center" if m > 12 else "right", rotation_mode="anchor" if m <= 12 else "default")
        ax.set_xlabel("reading j (instrument:station)" if r == len(picks) - 1 else "reading j")
        ax.grid(True, axis="y", color="0.9", lw=0.6)
        ax.set_axisbelow(True)
        if r == 0:
            ax.legend(handles=[Patch(color=inst_colour[nm], label=nm) for nm in instruments], ncols=len(instruments),
                      loc="upper left", fontsize=8, framealpha=0.9)
    axh = fig.add_subplot(gs[:, 1])
    im = axh.imshow(Q, cmap="RdBu_r", norm=TwoSlopeNorm(0.0, -vmax, vmax), interpolation="nearest",
                    extent=(0.5, m + 0.5, m + 0.5, 0.5), aspect="auto")
    if show_ticks:
        axh.set_xticks(idx)
        axh.set_yticks(idx)
        axh.set_xticklabels(short, rotation=90, fontsize=7 if m > 20 else 8)
        axh.set_yticklabels(short, fontsize=7 if m > 20 else 8)
    # instrument separators
    bounds = np.flatnonzero([labels[k].instrument != labels[k - 1].instrument for k in range(1, m)]) + 1.5
    for bnd in bounds:
        axh.axhline(bnd, color="k", lw=0.8)
        axh.axvline(bnd, color="k", lw=0.8)
    axh.set_xlabel("reading j")
    axh.set_ylabel("reading i")
    axh.set_title(f"Information density matrix Q (trace = {np.trace(Q):.2f})", fontsize=10)
    if res.objective.weighting == "full" and any(b.integration is not None for b in pr.obs.blocks):
        fig.suptitle("Q relates the whitened readings L⁻¹x (full weighting): for linewise instruments "
                     "the i-th whitened reading is essentially the i-th primary (incremental) reading",
                     fontsize=9.5, color="0.25")
    cb = fig.colorbar(im, ax=axh, shrink=0.95, pad=0.02)
    cb.set_label("Q_ij [-]")
    return fig


def _line_geometry(block):
    """Reference end, unit direction and arc length of the stations of a linewise instrument."""
    s = np.cumsum(block.lengths)
    pts = block.points
    if len(pts) >= 2:
        d = pts[-1] - pts[0]
        d = d / np.linalg.norm(d)
    else:
        d = np.array([0.0, -1.0])
    start = pts[0] - s[0] * d
    return start, d, s


def instruments_figure(res, before: np.ndarray | None = None, before_label: str = "before",
                       title: str | None = None) -> Figure:
    """Measured and computed readings along every instrument, +-2 sigma from diag C_x; `before`
    adds another model's readings (e.g. the baseline of a diagnosis) as a dashed red line."""
    pr, f = res.problem, res.fit
    obs = pr.obs
    blocks = obs.blocks
    nb = len(blocks)
    ncols = min(nb, 3)
    nrows = int(np.ceil(nb / ncols))
    fig = _new_figure(4.9 * ncols + 0.6, 5.2 * nrows)
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False)).ravel()
    measured, computed = res.objective.measured, f.x
    sigma = np.sqrt(np.clip(np.diag(obs.covariance), 0, None))
    rw = obs.whiten(measured - computed)  # whitened with the case's C_x
    u_free = pr.displacement(pr.values_for(f.p))
    identified = {n for n in pr.params.names if n.split("[")[0] in ("A", "B", "C", "D")}
    mm = 1e3
    row0 = 0
    for ax, block in zip(axes, blocks):
        rows = np.arange(row0, row0 + len(block.labels))
        row0 += len(block.labels)
        xm, xc, sg, r_ = measured[rows] * mm, computed[rows] * mm, sigma[rows] * mm, rw[rows]
        xb = before[rows] * mm if before is not None else None
        chi2_block = float(r_ @ r_)
        linewise = block.integration is not None
        if linewise:
            w0 = block.weights[0, 0]  # the measured direction (the same at every station)
            what = {"inclinometer": "horizontal displacement u_x", "deflectometer": "displacement normal to the line"
                    }.get(block.kind, "displacement along the line")
            what += f" ({_direction_words(w0)})"
        if linewise:
            start, d, s = _line_geometry(block)
            vertical = abs(d[1]) >= abs(d[0])
            coord = -block.points[:, 1] if vertical else block.points[:, 0]
            dense = None
            if not any(n.endswith(f"[{block.name}]") for n in identified):
                t = np.linspace(0.0, s[-1], 160)
                P = start[None] + t[:, None] * d[None]
                try:
                    Ix, Iy = pr.fe.interpolation(P)
                    w = block.weights[0, 0]
                    dense = ((w[0] * (Ix @ u_free) + w[1] * (Iy @ u_free)) * mm,
                             -P[:, 1] if vertical else P[:, 0])
                except ValueError:
                    dense = None
            # draw (value, coordinate) pairs: depth downwards for vertical lines, x across otherwise
            pair = (lambda v, c: (v, c)) if vertical else (lambda v, c: (c, v))
            (ax.fill_betweenx if vertical else ax.fill_between)(coord, xm - 2 * sg, xm + 2 * sg, color="0.55",
                                                                alpha=0.25, lw=0, label="measured ± 2σ (case C_x)")
            if dense is not None:
                ax.plot(*pair(dense[0], dense[1]), color="#1f77b4", lw=1.2, alpha=0.7, label="model along the line")
            ax.plot(*pair(xc, coord), ls="none", marker="o", ms=6, mfc="white", mec="#1f77b4", mew=1.6,
                    label="computed at stations")
            if xb is not None:
                ax.plot(*pair(xb, coord), ls="--", marker="s", ms=3.5, lw=1.2, color=BEFORE, label=before_label)
            ax.plot(*pair(xm, coord), ls="none", marker="x", ms=7, mew=1.8, color="k", label="measured")
            (ax.axvline if vertical else ax.axhline)(0, color="0.7", lw=0.7, zorder=0)
            if vertical:
                ax.invert_yaxis()
                ax.set_ylabel("depth below the surface [m]")
                ax.set_xlabel(f"{what} [mm]")
                tr = blended_transform_factory(ax.transAxes, ax.transData)
                for c_, rv in zip(coord, r_):
                    ax.text(1.01, c_, f"{rv:+.2f}", transform=tr, fontsize=7.5, va="center", ha="left",
                            color="#b22222" if abs(rv) > 2 else "0.25")
                ax.text(1.01, 1.0, "r′", transform=ax.transAxes, fontsize=8, va="bottom", ha="left",
                        fontweight="bold")
            else:
                ax.set_xlabel("horizontal distance from the symmetry axis x [m]")
                ax.set_ylabel(f"{what} [mm]")
                tr = blended_transform_factory(ax.transData, ax.transAxes)
                for c_, rv in zip(coord, r_):  # residuals along the top, inside the frame
                    ax.text(c_, 0.985, f"{rv:+.2f}", transform=tr, fontsize=7, va="top", ha="center",
                            rotation=90 if len(coord) > 8 else 0, color="#b22222" if abs(rv) > 2 else "0.25",
                            bbox=dict(boxstyle="round,pad=0.1", fc="white", ec="none", alpha=0.7))
                lo_, hi_ = ax.get_ylim()
                ax.set_ylim(lo_, hi_ + 0.12 * (hi_ - lo_))  # room for the residuals
        else:
            k = np.arange(1, len(rows) + 1)
            ax.errorbar(k, xm, yerr=2 * sg, ls="none", marker="x", ms=7, mew=1.8, color="k", capsize=4,
                        elinewidth=1.0, label="measured ± 2σ (case C_x)")
            ax.plot(k, xc, ls="none", marker="o", ms=6, mfc="white", mec="#1f77b4", mew=1.6, label="computed")
            if xb is not None:
                ax.plot(k, xb, ls="none", marker="s", ms=5, color=BEFORE, label=before_label)
            ax.set_xticks(k)
            if block.kind == "points":
                ax.set_xticklabels([f"{lab.component} at ({lab.x:g}, {lab.y:g})" for lab in block.labels],
                                   rotation=35, ha="right", rotation_mode="anchor")
                ax.set_xlabel("reading: component at point (x, y) [m]")
                ax.set_ylabel("displacement [mm]\n(u_x + away from the axis, u_y + up)")
            else:
                ax.set_xticklabels([f"chord {lab.station}" for lab in block.labels])
                ax.set_xlabel("chord")
                ax.set_ylabel("change of chord length (+ lengthening) [mm]")
            ax.set_xlim(0.4, len(rows) + 0.6)
            for k_, y_, rv in zip(k, xm, r_):
                ax.annotate(f"r′={rv:+.2f}", (k_, y_), xytext=(6, 0), textcoords="offset points", fontsize=7.5,
                            va="center", color="#b22222" if abs(rv) > 2 else "0.25")
        ax.set_title(f"{block.name} ({block.kind}, {len(rows)} readings)", fontsize=10)
        ax.text(0.03, 0.03, f"Σ r′² = {chi2_block:.3g}\nmax |r′| = {np.max(np.abs(r_)):.3g}",
                transform=ax.transAxes, fontsize=8, va="bottom", ha="left",
                bbox=dict(boxstyle="round,pad=0.3", fc="white", ec="0.7", alpha=0.9))
        ax.grid(True, color="0.92", lw=0.6)
        ax.set_axisbelow(True)
    for ax in axes[nb:]:
        ax.set_visible(False)
    handles = [Patch(color="0.55", alpha=0.25, label="measured ± 2σ (σ from diag C_x of the case)"),
               Line2D([], [], color="#1f77b4", lw=1.2, alpha=0.7, label="model along the line (at p̂)"),
               Line2D([], [], ls="none", marker="o", ms=6, mfc="white", mec="#1f77b4", mew=1.6,
                      label="computed at the stations"),
               Line2D([], [], ls="none", marker="x", ms=7, mew=1.8, color="k", label="measured"),
               Line2D([], [], ls="none", marker="$r′$", ms=9, color="0.25",
                      label="whitened residual r′ = L⁻¹(x* − x(p̂)) (red if |r′| > 2)")]
    if before is not None:
        handles.append(Line2D([], [], ls="--", marker="s", ms=3.5, lw=1.2, color=BEFORE, label=before_label))
    fig.legend(handles=handles, loc="outside lower center", ncols=3, fontsize=8.5, frameon=False)
    fig.suptitle(title or f"Measured and computed readings at the estimate (fit: {res.objective.weighting} "
                          f"weighting; σ and whitened residuals r′ from the case's C_x)", fontsize=10.5)
    return fig


BEFORE = "#d62728"  # colour of a second model's readings (a diagnosis' baseline)


def _direction_words(v: np.ndarray) -> str:
    """'+ downwards' etc. for a measured direction vector (x away from the axis, y up)."""
    v = np.asarray(v, float)
    if abs(v[1]) < 1e-9 * np.hypot(*v):
        return "+ away from the axis" if v[0] > 0 else "+ towards the axis"
    if abs(v[0]) < 1e-9 * np.hypot(*v):
        return "+ upwards" if v[1] > 0 else "+ downwards"
    return f"+ along ({v[0]:.2f}, {v[1]:.2f})"


def _value_text(params, k: int, value: float) -> str:
    fct, unit = _display(params.names[k], params.units[k], value)
    return f"{value * fct:.4g}" + (f" {unit}" if unit not in ("-", "") else "")


def _estimate_text(params, p) -> str:
    return ", ".join(f"{name} = {_value_text(params, k, p[k])}" for k, name in enumerate(params.names))


def field_figure(res) -> Figure:
    """Deformed mesh coloured by |u|, magnified, with the instruments (corner-node triangulation)."""
    pr, f = res.problem, res.fit
    mesh, g = pr.mesh, pr.case.geometry
    ufree = pr.displacement(pr.values_for(f.p))
    u = pr.fe.expand(ufree).reshape(-1, 2)  # (N, 2) nodal displacements
    umag = np.hypot(u[:, 0], u[:, 1])
    umax = float(umag.max()) if umag.size else 0.0
    factor = _nice_factor(FIELD_TARGET * g.radius / umax) if umax > 0 else 1.0
    xy = mesh.nodes + factor * u
    T = Triangulation(xy[:, 0], xy[:, 1], mesh.triangles[:, :3])
    inst = []  # (block, displaced stations, displaced line or None)
    for block in pr.obs.blocks:
        line = None
        if block.integration is not None:
            start, d, s = _line_geometry(block)
            line = start[None] + np.linspace(0, s[-1], 60)[:, None] * d[None]
        pts = block.points if line is None else np.vstack([block.points, line])
        moved = pts.copy()
        inside = pr.fe.locate(pts)[0] >= 0
        if inside.any():
            Ix, Iy = pr.fe.interpolation(pts[inside])
            moved[inside] += factor * np.column_stack([Ix @ ufree, Iy @ ufree])
        n = len(block.points)
        if block.kind == "convergence":  # a straight chord between its two (displaced) ends
            line_moved = moved[:n]
        else:
            line_moved = None if line is None else moved[n:]
        inst.append((block, moved[:n], line_moved))
    cx, cy, R = 0.0, -g.axis_depth, g.radius
    # zoom on the tunnel: about 2.5 radii around it, cut at the ground surface
    zx = (-0.04 * 2.6 * R, min(g.width, 2.6 * R))
    ztop = 0.0 if cy + 2.4 * R > -1.2 * R else cy + 2.4 * R  # keep a shallow cover whole
    zy = (max(-g.depth, cy - 2.4 * R), ztop + 0.04 * 2.6 * R)
    full_x, full_y = (-0.02 * g.width, 1.02 * g.width), (-1.02 * g.depth, 0.04 * g.depth)
    ratios = [(full_x[1] - full_x[0]) / (full_y[1] - full_y[0]), (zx[1] - zx[0]) / (zy[1] - zy[0])]
    fig = _new_figure(4.9 * (ratios[0] + ratios[1]) + 1.6, 5.6)
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
        ax.plot(cx + R * np.cos(theta), cy + R * np.sin(theta), color="#1f77b4", lw=1.4, ls="--",
                label="tunnel wall before excavation")
        ax.plot([0, g.width, g.width, 0, 0], [0, 0, -g.depth, -g.depth, 0], color="0.35", lw=0.9, ls=":",
                label="model boundary before excavation")
        for li, layer in enumerate(pr.case.ground.layers[1:]):
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
            corner[mesh.triangles[:, :3].ravel()] = True
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
    est = textwrap.fill(f"({_estimate_text(pr.params, f.p)})", 110)
    fig.suptitle(f"{pr.case.name}: excavation-induced displacements at the estimate\n{est}\n"
                 f"max |u| = {umax * 1e3:.1f} mm; deformation magnified ×{factor:g} "
                 f"(max |u| drawn as {factor * umax / R:.0%} of the tunnel radius R = {R:g} m)", fontsize=10.5)
    return fig


# ------------------------------------------------------------------------------- entry points
def _other_fit(res):
    """The other method (GN if the run used LM, else LM) on the same problem, from the same start."""
    from .estimate import fit

    method = _other_method(res.fit.method)
    try:
        return fit(res.problem, method=method, weighting=res.objective.weighting), ""
    except Exception as exc:  # noqa: BLE001 - the figure is still useful with one path
        return None, f"{METHOD_NAMES.get(method, method)} failed: {exc}"


def build_figures(res, names: tuple[str, ...] = FIGURES, other: bool = True) -> dict[str, Figure]:
    """Every figure of the run, by name. The problem's counters are left as they were."""
    unknown = [n for n in names if n not in FIGURES]
    if unknown:
        raise ValueError(f"unknown figure(s): {', '.join(unknown)} (figures: {', '.join(FIGURES)})")
    pr = res.problem
    saved = copy.deepcopy(pr.counters)
    figs: dict[str, Figure] = {}
    try:
        with matplotlib.rc_context(RC):
            other_fit = None
            if other and ("objective_contours" in names or "convergence" in names):
                other_fit, _note = _other_fit(res)
            for name in names:
                if name == "objective_contours":
                    figs[name] = objective_contours_figure(res, other_fit)
                elif name == "convergence":
                    figs[name] = convergence_figure(res, other_fit)
                elif name == "information_density":
                    figs[name] = information_density_figure(res)
                elif name == "instruments":
                    figs[name] = instruments_figure(res)
                elif name == "field":
                    figs[name] = field_figure(res)
    finally:  # in place: problems derived from this one share the counters object
        vars(pr.counters).update(vars(saved))
    return figs


def _compact_png(data: bytes) -> bytes:
    """The PNG with an adaptive 256-colour palette (a third of the size, no visible change)."""
    try:
        from PIL import Image

        im = Image.open(io.BytesIO(data)).convert("RGB")
        q = im.quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
        buf = io.BytesIO()
        q.save(buf, format="PNG", optimize=True)
        return buf.getvalue() if buf.tell() < len(data) else data
    except Exception:  # noqa: BLE001 - Pillow missing or too old: keep matplotlib's PNG
        return data


def save_figures(figs: dict[str, Figure], out: Path, formats: tuple[str, ...] = FORMATS,
                 dpi: int = DPI, compact: bool = True) -> list[Path]:
    """Write each figure as out/<name>.<format> (atomically); return the paths.

    compact: store PNGs with a 256-colour palette (Pillow), about three times smaller."""
    out = Path(out)
    paths = []
    with matplotlib.rc_context(RC):
        for name, fig in figs.items():
            for fmt in formats:
                buf = io.BytesIO()
                meta = {"Date": None} if fmt == "svg" else {"Software": None} if fmt == "png" else None
                fig.savefig(buf, format=fmt, dpi=dpi, metadata=meta)
                data = buf.getvalue()
                if fmt == "png" and compact:
                    data = _compact_png(data)
                path = out / f"{name}.{fmt}"
                write_atomic(path, data)
                paths.append(path)
    return paths


def plot_run(res, out: Path, formats: tuple[str, ...] = FORMATS) -> list[Path]:
    """Build every figure of the run and write PNG and SVG files into `out`; return the paths."""
    figs = build_figures(res)
    try:
        return save_figures(figs, out, formats)
    finally:
        for fig in figs.values():
            fig.clear()
