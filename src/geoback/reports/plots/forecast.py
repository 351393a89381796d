"""One figure per forecast: the forecast at the estimate with its 95 % band (linearised, and the
range sampled through the model), the alert level, along the line, the instrument or the lining."""
from __future__ import annotations

import numpy as np

from geoback.reports.plots.common import Figure
from geoback.reports.forecast_report import SHOW, WHAT

BAND = "#1f77b4"
SAMPLED = "#555555"
ALERT = "#d62728"


def _scale(unit: str) -> tuple[float, str]:
    return SHOW.get(unit, (1.0, unit))


def _profile(ax, fc, rows, vertical: bool) -> None:
    """Value and bands along a position (depth downwards when `vertical`)."""
    f, unit = _scale(fc.unit[rows[0]])
    pos = fc.position[rows]
    order = np.argsort(pos)
    r, pos = rows[order], pos[order]
    val, lo, hi = f * fc.value[r], f * fc.low[r], f * fc.high[r]
    fill = ax.fill_betweenx if vertical else ax.fill_between
    plot = (lambda a, b, **k: ax.plot(b, a, **k)) if vertical else (lambda a, b, **k: ax.plot(a, b, **k))
    fill(pos, lo, hi, color=BAND, alpha=0.25, lw=0, label="95 % band (linearised)")
    plot(pos, val, color=BAND, lw=1.8, label="forecast at the estimate")
    if fc.sampled_low is not None:
        plot(pos, f * fc.sampled_low[r], color=SAMPLED, lw=1.0, ls="--", label=f"95 % range, {fc.draws} draws")
        plot(pos, f * fc.sampled_high[r], color=SAMPLED, lw=1.0, ls="--")
    alert = fc.alert[r[0]]
    if np.isfinite(alert):
        line = ax.axvline if vertical else ax.axhline
        for s in (-1, 1):
            if (s < 0 and lo.min() < 0) or (s > 0 and hi.max() > 0):
                line(s * f * alert, color=ALERT, lw=1.0, ls=":", label="alert level")
    q = fc.quantity[r[0]]
    what = f"{WHAT.get(q, q)} [{unit}]"
    if vertical:
        ax.set_xlabel(what)
        ax.set_ylabel(fc.position_label[r[0]])
        ax.invert_yaxis()
    else:
        ax.set_xlabel(fc.position_label[r[0]])
        ax.set_ylabel(what)
    ax.axhline(0, color="0.6", lw=0.6) if not vertical else ax.axvline(0, color="0.6", lw=0.6)


def _points(ax, fc, rows) -> None:
    f, unit = _scale(fc.unit[rows[0]])
    k = np.arange(len(rows))
    labels = [f"({fc.x[i]:.3g}, {fc.y[i]:.3g}) {fc.quantity[i]}" for i in rows]
    val = f * fc.value[rows]
    ax.errorbar(k, val, yerr=[val - f * fc.low[rows], f * fc.high[rows] - val], fmt="o", color=BAND, capsize=4,
                label="forecast, 95 % band")
    if fc.sampled_low is not None:
        ax.errorbar(k + 0.15, val, yerr=[val - f * fc.sampled_low[rows], f * fc.sampled_high[rows] - val], fmt="none",
                    color=SAMPLED, capsize=3, ls="--", label=f"95 % range, {fc.draws} draws")
    ax.set_xticks(k, labels, rotation=20 if len(k) > 3 else 0)
    ax.set_ylabel(f"forecast [{unit}]")
    ax.axhline(0, color="0.6", lw=0.6)


def forecast_figure(fc, name: str) -> Figure:
    rows = fc.rows(name)
    kind, stage = fc.kind[rows[0]], fc.stage[rows[0]]
    quantities = list(dict.fromkeys(fc.quantity[i] for i in rows))
    if kind == "lining":
        fig = Figure(figsize=(6.4, 2.6 * len(quantities)))
        axes = fig.subplots(len(quantities), 1, sharex=True, squeeze=False)[:, 0]
        for ax, q in zip(axes, quantities):
            _profile(ax, fc, np.array([i for i in rows if fc.quantity[i] == q]), vertical=False)
        axes[-1].set_xlabel("angle from the crown [°]")
        for ax in axes[:-1]:
            ax.set_xlabel("")
    else:
        vertical = fc.position_label[rows[0]].startswith("depth")
        fig = Figure(figsize=(4.6, 5.2) if vertical else (6.4, 3.8))
        ax = fig.subplots()
        if kind in ("points", "convergence"):
            _points(ax, fc, rows)
        else:
            _profile(ax, fc, rows, vertical)
        axes = [ax]
    axes[0].legend(loc="best", frameon=False)
    fig.suptitle(f"Forecast '{name}' after stage '{stage}' with its 95 % band")
    return fig


def forecast_figures(fc) -> dict:
    """{'forecast_<name>': Figure} for every forecast."""
    return {f"forecast_{name}": forecast_figure(fc, name) for name in fc.names}
