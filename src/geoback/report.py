"""Outputs of `geoback run`: CSV tables, summary.json, report.md and field.vtu.

Readers only: everything comes from the frozen ``Identification`` and, for the field and the
figures, from the ``Exploration``; nothing here runs the model.
"""
from __future__ import annotations

import platform
from pathlib import Path

import numpy as np

from . import __version__
from .outputs import write_atomic, write_csv, write_json, write_matrix_csv


def reading_label(lab, staged: bool = False) -> str:
    """instrument:station:component, and @stage when readings come from several construction stages."""
    return f"{lab.instrument}:{lab.station}:{lab.component}" + (f"@{lab.stage}" if staged else "")


def several_stages(labels) -> bool:
    return len({lab.stage for lab in labels}) > 1


def summary(res, exploration=None) -> dict:
    f, rel, params = res.fit, res.reliability, res.parameters
    lo, hi = rel.interval95()
    out = {
        "case": res.name,
        "case_hash": res.case_hash,
        "geoback_version": __version__,
        "status": f.status,
        "stop_reason": f.reason,
        "method": f.method,
        "weighting": res.weighting,
        "iterations": f.iterations,
        "parameters": {n: {"unit": params.units[i], "initial": params.initial[i], "estimate": f.p[i],
                           "std": rel.std[i], "ci95": [lo[i], hi[i]], "at_bound": bool(f.at_bound[i])}
                       for i, n in enumerate(params.names)},
        "J": f.J, "chi2": rel.chi2, "dof": rel.dof, "reduced_chi2": rel.reduced_chi2, "p_value": rel.p_value,
        "minus_2_log_likelihood": rel.minus2logL, "aic": rel.aic, "bic": rel.bic,
        "condition_number": rel.condition, "undetermined": rel.undetermined,
        "readings": res.data.m, "dofs": res.dofs, "elements": res.elements,
        **res.counts, "solver": res.solver,
        "timings_s": {k: round(v, 4) for k, v in res.seconds.items()},
        "platform": platform.platform(),
    }
    if exploration is not None:  # the work of the field file and figures, apart from the identification's
        out["exploration"] = {k: exploration.counts.get(k, 0) for k in ("factorisations", "solves", "forward_runs")}
        out["timings_s"]["exploration"] = round(exploration.seconds, 4)
    return out


def report_text(res) -> str:
    """A one-page report in the spirit of lmfit's fit_report."""
    f, rel, params = res.fit, res.reliability, res.parameters
    lines = [f"# geoback fit report: {res.name}", ""]
    lines += [f"- status: **{f.status}** ({f.reason})",
              f"- method: {f.method}, {f.iterations} iterations, {res.counts['factorisations']} factorisation(s), "
              f"{res.counts['solves']} solves",
              f"- readings m = {res.data.m}, parameters n = {params.n}, dofs = {res.dofs}",
              f"- chi-square = {rel.chi2:.6g}, dof = {rel.dof}, reduced chi-square = {rel.reduced_chi2:.4g}, "
              f"p-value = {rel.p_value:.3g}",
              f"- AIC = {rel.aic:.6g}, BIC = {rel.bic:.6g}, condition number = {rel.condition:.3g}", "",
              "| parameter | unit | initial | estimate | std | 95 % interval |", "|---|---|---|---|---|---|"]
    lo, hi = rel.interval95()
    for i, n in enumerate(params.names):
        pct = f" ({100 * rel.std[i] / abs(f.p[i]):.2g} %)" if f.p[i] != 0 and np.isfinite(rel.std[i]) else ""
        bound = " (at bound)" if f.at_bound[i] else ""
        lines.append(f"| {n} | {params.units[i]} | {params.initial[i]:.6g} | {f.p[i]:.6g}{bound} | "
                     f"{rel.std[i]:.3g}{pct} | [{lo[i]:.6g}, {hi[i]:.6g}] |")
    strong = [(params.names[i], params.names[j], rel.correlation[i, j])
              for i in range(params.n) for j in range(i + 1, params.n)
              if np.isfinite(rel.correlation[i, j]) and abs(rel.correlation[i, j]) > 0.5]
    if strong:
        lines += ["", "Correlations above 0.5: " + ", ".join(f"C({a}, {b}) = {c:+.3f}" for a, b, c in strong)]
    top = np.argsort(-rel.leverage)[:3]
    lines += ["", "Most informative readings (leverage = diag Q): " +
              ", ".join(f"{reading_label(res.data.labels[i], several_stages(res.data.labels))} "
                        f"({rel.leverage[i]:.2f})" for i in top)]
    warnings = []
    if f.status != "converged":
        warnings.append(f"the fit did not converge: {f.reason}")
    if rel.undetermined:
        warnings.append("the readings cannot determine: " + "; ".join(rel.undetermined) +
                        " (standard deviations of the parameters involved are infinite)")
    if rel.dof > 0 and rel.p_value < 0.05:
        warnings.append(f"chi-square is too large for the stated measurement errors (p = {rel.p_value:.2g}): "
                        "the model may be missing physics - try `geoback diagnose`")
    if f.at_bound.any():
        warnings.append("at a bound: " + ", ".join(n for n, b in zip(params.names, f.at_bound) if b))
    if warnings:
        lines += ["", "Warnings:"] + [f"- {w}" for w in warnings]
    return "\n".join(lines) + "\n"


def write_field(field, path: Path) -> None:
    """Displacement (point data) and cell data (stresses, ...) as VTU for ParaView; more point data
    (the displacement after every construction stage) if the field has it."""
    from .mesh import write_mesh

    def vec(v):
        v = np.asarray(v)
        return np.column_stack([v, np.zeros(len(v))]) if v.ndim == 2 and v.shape[1] == 2 else v

    point = {"displacement": vec(field.displacement)}
    point.update({k: vec(v) for k, v in getattr(field, "point_data", {}).items()})
    write_mesh(field.mesh, path, point_data=point, cell_data=field.cell_data)


def write_run(res, out: Path, exploration=None, plots: bool = False) -> None:
    """Every file of a run into `out`; the field (field.vtu) and figures if the exploration has them."""
    f, rel, params = res.fit, res.reliability, res.parameters
    names = params.names
    out = Path(out)
    lo, hi = rel.interval95()
    write_csv(out / "parameters.csv",
              ["name", "unit", "initial", "estimate", "std", "ci95_low", "ci95_high", "at_bound"],
              [[n, params.units[i], params.initial[i], f.p[i], rel.std[i], lo[i], hi[i], bool(f.at_bound[i])]
               for i, n in enumerate(names)])
    write_matrix_csv(out / "covariance.csv", names, rel.covariance)
    write_matrix_csv(out / "correlation.csv", names, rel.correlation)
    write_csv(out / "eigen.csv", ["index", "singular_value"] + [f"v_{n}" for n in names],
              [[i + 1, rel.singular_values[i]] + list(rel.directions[:, i]) for i in range(len(rel.singular_values))])
    staged = several_stages(res.data.labels)
    labels = [reading_label(lab, staged) for lab in res.data.labels]
    write_matrix_csv(out / "information_density.csv", labels, rel.information_density)
    measured = res.data.measured
    residual = measured - f.x
    write_csv(out / "readings.csv",
              ["instrument", "kind", "station", "component", "stage", "x", "y", "measured", "computed", "residual",
               "whitened_residual", "leverage"],
              [[lab.instrument, lab.kind, lab.station, lab.component, lab.stage, lab.x, lab.y, measured[i],
                f.x[i], residual[i], rel.whitened_residual[i], rel.leverage[i]] for i, lab in enumerate(res.data.labels)])
    write_csv(out / "iterations.csv", ["iteration", "mu", "J"] + names + ["accepted"],
              [[h.k, h.mu, h.J] + list(h.p) + [h.accepted] for h in f.history])
    if exploration is not None and exploration.field is not None:
        write_field(exploration.field, out / "field.vtu")
    if exploration is not None and getattr(exploration, "lining", None) is not None:
        from .lining import write_lining

        write_lining(exploration.lining, out, vtu=exploration.field is not None)
    if plots:
        from .plots import plot_run

        plot_run(res, exploration, out)
    write_atomic(out / "report.md", report_text(res))
    write_json(out / "summary.json", summary(res, exploration))
