"""Outputs of `geoback run` (DESIGN.md): CSV tables, summary.json, report.md, field.vtu."""
from __future__ import annotations

import platform
from pathlib import Path

import numpy as np

from . import __version__
from .outputs import result_set, write_atomic, write_csv, write_json, write_matrix_csv


def reading_label(lab) -> str:
    return f"{lab.instrument}:{lab.station}:{lab.component}"


def summary(res) -> dict:
    pr, f, rel = res.problem, res.fit, res.reliability
    lo, hi = rel.interval95()
    params = pr.params
    return {
        "case": pr.case.name,
        "case_hash": pr.loaded.digest(),
        "geoback_version": __version__,
        "status": f.status,
        "stop_reason": f.reason,
        "method": f.method,
        "weighting": res.objective.weighting,
        "iterations": f.iterations,
        "parameters": {n: {"unit": params.units[i], "initial": params.initial[i], "estimate": f.p[i],
                           "std": rel.std[i], "ci95": [lo[i], hi[i]], "at_bound": bool(f.at_bound[i])}
                       for i, n in enumerate(params.names)},
        "J": f.J, "chi2": rel.chi2, "dof": rel.dof, "reduced_chi2": rel.reduced_chi2, "p_value": rel.p_value,
        "minus_2_log_likelihood": rel.minus2logL, "aic": rel.aic, "bic": rel.bic,
        "condition_number": rel.condition, "undetermined": rel.undetermined,
        "readings": pr.obs.m, "dofs": pr.fe.ndof, "elements": pr.fe.ne,
        **f.counts, "solver": pr._factor[1].backend if pr._factor else None,
        "timings_s": {k: round(v, 4) for k, v in res.seconds.items()},
        "platform": platform.platform(),
    }


def report_text(res) -> str:
    """A one-page report in the spirit of lmfit's fit_report."""
    pr, f, rel = res.problem, res.fit, res.reliability
    params = pr.params
    lines = [f"# geoback fit report: {pr.case.name}", ""]
    lines += [f"- status: **{f.status}** ({f.reason})",
              f"- method: {f.method}, {f.iterations} iterations, {f.counts['factorisations']} factorisation(s), "
              f"{f.counts['solves']} solves",
              f"- readings m = {pr.obs.m}, parameters n = {params.n}, dofs = {pr.fe.ndof}",
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
              ", ".join(f"{reading_label(pr.obs.labels[i])} ({rel.leverage[i]:.2f})" for i in top)]
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


def write_run(res, out: Path, vtu: bool = True, plots: bool = False) -> None:
    """Every output of a run, replacing the previous run's set in `out` as a whole (outputs.result_set)."""
    with result_set(out, "run") as staging:
        _write_run(res, staging, vtu=vtu, plots=plots)


def _write_run(res, out: Path, vtu: bool, plots: bool) -> None:
    pr, f, rel = res.problem, res.fit, res.reliability
    params, names = pr.params, pr.params.names
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
    labels = [reading_label(lab) for lab in pr.obs.labels]
    write_matrix_csv(out / "information_density.csv", labels, rel.information_density)
    residual = res.objective.measured - f.x
    write_csv(out / "readings.csv",
              ["instrument", "kind", "station", "component", "x", "y", "measured", "computed", "residual",
               "whitened_residual", "leverage"],
              [[lab.instrument, lab.kind, lab.station, lab.component, lab.x, lab.y, res.objective.measured[i],
                f.x[i], residual[i], rel.whitened_residual[i], rel.leverage[i]] for i, lab in enumerate(pr.obs.labels)])
    write_csv(out / "iterations.csv", ["iteration", "mu", "J"] + names + ["accepted"],
              [[h.k, h.mu, h.J] + list(h.p) + [h.accepted] for h in f.history])
    if vtu:
        from .simulate import write_field

        write_field(pr, pr.values_for(f.p), out / "field.vtu")
    if plots:
        from .plots import plot_run

        plot_run(res, out)
    write_atomic(out / "report.md", report_text(res))
    write_json(out / "summary.json", summary(res))
