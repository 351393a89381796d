"""`geoback design`'s figure: how much each candidate instrument would narrow the target, and along
a varied position (e.g. the offset of an inclinometer from the tunnel axis) where there is one."""
from __future__ import annotations

import numpy as np

from geoback.reports.plots.common import Figure

UNITS = {"x": "m", "toe_depth": "m", "head_depth": "m", "spacing": "m", "sigma": "", "stations": ""}
WORDS = {"x": "offset from the tunnel axis x", "toe_depth": "depth of the toe", "head_depth": "depth of the head",
         "spacing": "station spacing", "stations": "number of stations", "sigma": "reading std"}


def design_figure(d) -> Figure:
    from geoback.reports.forecast_report import SHOW

    families = [f for f in dict.fromkeys(d.family)
                if all(d.varied[k] is not None and isinstance(d.varied[k][1], (int, float))
                       for k in range(len(d.names)) if d.family[k] == f)]
    order = d.ranking[:15][::-1]
    two = bool(families)
    fig = Figure(figsize=(10.0 if two else 6.4, max(3.0, 0.32 * len(order) + 1.2)))
    axes = fig.subplots(1, 2 if two else 1, squeeze=False)[0]
    ax = axes[0]
    ax.barh(np.arange(len(order)), 100 * d.reduction[order], color="#1f77b4")
    ax.set_yticks(np.arange(len(order)), [f"{d.names[k]} ({d.stages[k]})" for k in order])
    what = "std of the forecasts" if d.objective == "forecasts" else "volume of the confidence ellipsoid"
    ax.set_xlabel(f"reduction of the {what} [%]")
    if two:
        ax = axes[1]
        f, unit = SHOW.get(d.unit, (1.0, d.unit)) if d.objective == "forecasts" else (1.0, "")
        for fam in families:
            ks = [k for k in range(len(d.names)) if d.family[k] == fam]
            field = d.varied[ks[0]][0]
            xs = np.array([d.varied[k][1] for k in ks], float)
            o = np.argsort(xs)
            ys = d.after[ks][o] * f if d.objective == "forecasts" else 100 * d.reduction[ks][o]
            ax.plot(xs[o], ys, "o-", label=f"{d.family_name[ks[0]]} ({d.kinds[ks[0]]}) by {field}")
        if d.objective == "forecasts":
            ax.axhline(d.before * f, color="0.4", ls="--", lw=1.0, label="now (without a candidate)")
            ax.set_ylabel(f"rms std of {', '.join(d.targets)} after [{unit}]")
        else:
            ax.set_ylabel("reduction of the ellipsoid's volume [%]")
        fields = {d.varied[k][0] for k in range(len(d.names)) if d.family[k] in families}
        ax.set_xlabel(" / ".join(WORDS.get(fl, fl) + (f" [{UNITS[fl]}]" if UNITS.get(fl) else "") for fl in sorted(fields)))
        ax.legend(frameon=False)
    fig.suptitle("Where one more instrument narrows the forecast most" if d.objective == "forecasts"
                 else "Where one more instrument narrows the parameters most")
    return fig
