"""Measured vs computed along each instrument, before and after adding the missing physics:
the instruments figure of `geoback run --plots` at the final model, with the baseline dashed."""
from __future__ import annotations

from pathlib import Path


def before_after_figure(d):
    from ..estimate import Objective
    from ..identification import RunResult
    from ..plots import instruments_figure

    final = d.final_problem
    res = RunResult(final, d.final_fit, d.final_reliability, Objective(final, final.case.fit.weighting), {})
    b, f = d.baseline_reliability, d.final_reliability
    after = " + ".join(s.hypothesis.title for s in d.accepted) or "nothing added"
    title = (f"{d.case}: baseline model (dashed red) and with {after} (blue): "
             f"χ²/dof {b.reduced_chi2:.3g} (p = {b.p_value:.2g}) → {f.reduced_chi2:.3g} (p = {f.p_value:.2g})")
    return instruments_figure(res, before=d.baseline_fit.x, before_label="baseline model (before)", title=title)


def plot_before_after(d, out: Path) -> list[Path]:
    from ..plots import save_figures

    return save_figures({"diagnosis": before_after_figure(d)}, out)
