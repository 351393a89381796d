"""Shared pieces of the figures: style, number display, labels of readings and parameters."""
from __future__ import annotations

import sys

import matplotlib

if "matplotlib.pyplot" not in sys.modules:  # never switch the backend of an interactive session
    matplotlib.use("Agg")

import numpy as np  # noqa: E402
from matplotlib import patheffects  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from geoback.units import shown  # noqa: E402

DPI = 150
HALO = [patheffects.withStroke(linewidth=2.5, foreground="white")]
BEFORE = "#d62728"  # colour of a second model's readings (a diagnosis' baseline)
METHOD_NAMES = {"lm": "Levenberg-Marquardt", "lm-scaled": "Levenberg-Marquardt (scaled)", "gn": "Gauss-Newton"}
METHOD_STYLE = {"lm": dict(color="#1f77b4", marker="o", ls="-"),
                "lm-scaled": dict(color="#1f77b4", marker="o", ls="-"),
                "gn": dict(color="#d62728", marker="s", ls="--")}
RC = {"font.size": 9.5, "axes.titlesize": 10.5, "axes.labelsize": 9.5, "legend.fontsize": 8.5,
      "xtick.labelsize": 8.5, "ytick.labelsize": 8.5, "axes.grid": False, "figure.dpi": DPI,
      "svg.hashsalt": "geoback", "savefig.bbox": "tight", "savefig.pad_inches": 0.08}



def display(name: str, unit: str, value: float) -> tuple[float, str]:
    """Factor and unit to show a parameter with (kPa moduli in MPa, from 1 GPa in GPa: ``units.shown``)."""
    return shown(unit, value)


def plain(v: float, digits: int = 3) -> str:
    """A number with `digits` significant digits, without e-notation between 1e-3 and 1e6 (1081, not
    1.08e+03)."""
    if not np.isfinite(v):
        return f"{v}"
    if 1e3 <= abs(v) < 1e6:
        return f"{v:.0f}"
    return f"{v:.{digits}g}"


def axis_label(params, i: int, value: float) -> str:
    f, unit = display(params.names[i], params.units[i], value)
    return f"{params.names[i]} [{unit}]"


def short_label(labels, i: int, multi: set[str]) -> str:
    lab = labels[i]
    s = f"{lab.instrument}:{lab.station}"
    return s + f" {lab.component}" if lab.instrument in multi else s


def multi_component(labels) -> set[str]:
    comps: dict[str, set[str]] = {}
    for lab in labels:
        comps.setdefault(lab.instrument, set()).add(lab.component)
    return {k for k, v in comps.items() if len(v) > 1}


def accepted_steps(history) -> list:
    """One entry per iteration: the accepted point (iteration 0 is the start)."""
    out = {}
    for h in history:
        if h.accepted:
            out[h.k] = h
    return [out[k] for k in sorted(out)]



def nice_factor(x: float) -> float:
    """Largest of 1, 2, 5 x 10^k not above x (at least 1)."""
    if not np.isfinite(x) or x <= 1:
        return 1.0
    k = np.floor(np.log10(x))
    for m in (5, 2, 1):
        if m * 10 ** k <= x:
            return float(m * 10 ** k)
    return float(10 ** k)


def new_figure(w: float, h: float) -> Figure:
    return Figure(figsize=(w, h), dpi=DPI, layout="constrained")


def section_frames(g) -> tuple:
    """Limits of the two panels of a cross-section (the whole half model; about 2.5 radii around the
    tunnel, cut at the ground surface) and their width ratios: (full_x, full_y, zoom_x, zoom_y, ratios)."""
    cy, R = -g.axis_depth, g.radius
    zx = (-0.04 * 2.6 * R, min(g.width, 2.6 * R))
    ztop = 0.0 if cy + 2.4 * R > -1.2 * R else cy + 2.4 * R  # keep a shallow cover whole
    zy = (max(-g.depth, cy - 2.4 * R), ztop + 0.04 * 2.6 * R)
    full_x, full_y = (-0.02 * g.width, 1.02 * g.width), (-1.02 * g.depth, 0.04 * g.depth)
    ratios = [(full_x[1] - full_x[0]) / (full_y[1] - full_y[0]), (zx[1] - zx[0]) / (zy[1] - zy[0])]
    return full_x, full_y, zx, zy, ratios


def direction_words(v: np.ndarray) -> str:
    """'+ downwards' etc. for a measured direction vector (x away from the axis, y up)."""
    v = np.asarray(v, float)
    if abs(v[1]) < 1e-9 * np.hypot(*v):
        return "+ away from the axis" if v[0] > 0 else "+ towards the axis"
    if abs(v[0]) < 1e-9 * np.hypot(*v):
        return "+ upwards" if v[1] > 0 else "+ downwards"
    return f"+ along ({v[0]:.2f}, {v[1]:.2f})"


def value_text(params, k: int, value: float) -> str:
    fct, unit = display(params.names[k], params.units[k], value)
    return f"{value * fct:.4g}" + (f" {unit}" if unit not in ("-", "") else "")


def estimate_text(params, p) -> str:
    return ", ".join(f"{name} = {value_text(params, k, p[k])}" for k, name in enumerate(params.names))

