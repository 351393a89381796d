"""Measured vs computed along each instrument, before and after adding the missing physics:
the instruments figure of `geoback run --plots` at the final model, with the baseline dashed and an
accepted layer boundary drawn at its depth with its 95 % interval."""
from __future__ import annotations

from pathlib import Path


def boundaries(d) -> list:
    """Every layer boundary the diagnosis accepted: its depth and 95 % interval (profile likelihood)."""
    from geoback.reports.plots.instruments import Boundary

    out = []
    for s in d.accepted:
        prof = d.depth_profile(s)
        if prof is None or not prof.z_hat == prof.z_hat:
            continue
        ci = f", 95 % {prof.interval_text()}" if prof.has_interval else ""
        out.append(Boundary(float(prof.z_hat), float(prof.low), float(prof.high),
                            f"identified boundary in '{prof.layer}' at {prof.z_hat:.3g} m depth{ci} (band)"))
    return out


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
                                  title=title, boundaries=boundaries(d))


def plot_before_after(d, out: Path, exploration=None) -> list[Path]:
    from geoback.reports.plots import save_figures

    return save_figures({"diagnosis": before_after_figure(d, exploration)}, out)
