"""Measured vs computed along each instrument, before and after adding the missing physics:
the instruments figure of `geoback run --plots` at the final model, with the baseline dashed."""
from __future__ import annotations

from pathlib import Path


def before_after_figure(d, exploration=None):
    """`exploration`: the model along the instruments at the final fit (``explore(d.final_misfit,
    d.final, ("profiles",))``), or None for the readings only."""
    import matplotlib

    from geoback.reports.plots import instruments_figure
    from geoback.reports.plots.common import RC

    b, f = d.baseline_reliability, d.final_reliability
    after = " + ".join(s.hypothesis.title for s in d.accepted) or "nothing added"
    title = (f"{d.case}: baseline model (dashed red) and with {after} (blue): "
             f"χ²/dof {b.reduced_chi2:.3g} (p = {b.p_value:.2g}) → {f.reduced_chi2:.3g} (p = {f.p_value:.2g})")
    with matplotlib.rc_context(RC):
        return instruments_figure(d.final, exploration, before=d.baseline_fit.x, before_label="baseline model (before)",
                                  title=title)


def plot_before_after(d, out: Path, exploration=None) -> list[Path]:
    from geoback.reports.plots import save_figures

    return save_figures({"diagnosis": before_after_figure(d, exploration)}, out)
