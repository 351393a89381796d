"""The figures of `geoback update`: each parameter's estimate with its 95 % interval after every
stage fitted (``history_figure``), and every survey of a stage against the band forecast before it
was read (``checks_figure``, standardised: (read - forecast) / std of a reading, with the 95 %
band at ± 1.96)."""
from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from geoback.reports.plots.common import new_figure
from geoback.units import shown
from geoback.worth.updating import Z95


def history_figure(steps, name: str) -> Figure | None:
    if not steps:
        return None
    names = steps[-1].result.parameters.names
    fig = new_figure(3.4 * len(names) + 0.6, 3.6)
    axes = fig.subplots(1, len(names), squeeze=False)[0]
    x = np.arange(len(steps))
    for j, (ax, n) in enumerate(zip(axes, names)):
        unit = steps[-1].result.parameters.units[j]
        f, u = shown(unit, steps[-1].result.fit.p[j])
        est, lo, hi = [], [], []
        for s in steps:
            i = s.result.parameters.names.index(n)
            low, high = s.result.intervals95()
            est.append(f * s.result.fit.p[i])
            lo.append(f * low[i])
            hi.append(f * high[i])
        est, lo, hi = map(np.asarray, (est, lo, hi))
        ax.fill_between(x, lo, hi, color="C0", alpha=0.18, lw=0, label="95 % interval")
        ax.plot(x, est, "o-", color="C0", label="estimate")
        ax.set_xticks(x, [s.stage for s in steps])
        ax.set_xlabel("fitted through stage")
        ax.set_ylabel(n + ("" if u in ("-", "") else f" [{u}]"))
        ax.grid(alpha=0.3)
        if j == 0:
            ax.legend(loc="best")
    fig.suptitle(f"{name}: parameters as construction proceeds")
    return fig


def checks_figure(steps, name: str) -> Figure | None:
    checks = [c for s in steps for c in s.checks]
    if not checks:
        return None
    fig = new_figure(max(6.0, 0.9 * len(checks) + 3.0), 4.0)
    ax = fig.subplots()
    for k, c in enumerate(checks):
        z = c.z
        ax.plot(np.full(len(z), k) + np.linspace(-0.25, 0.25, len(z)), z, "o", ms=4,
                color="C3" if np.any(np.abs(z) > Z95) else "C0")
    ax.axhspan(-Z95, Z95, color="0.85", zorder=0, label="95 % band of the forecast")
    ax.axhline(0, color="0.4", lw=0.8)
    ax.set_xticks(range(len(checks)), [f"{c.instrument}\n{c.survey or c.stage}\n(forecast by {c.fitted})"
                                       for c in checks], fontsize=7.5)
    ax.set_ylabel("read − forecast, in std of a reading [-]")
    ax.legend(loc="upper right")
    ax.grid(axis="y", alpha=0.3)
    fig.suptitle(f"{name}: each survey against the forecast made before it was read")
    return fig
