"""Outputs of `geoback run`: CSV tables, summary.json, report.md and field.vtu.

Readers only: everything comes from the frozen ``Identification`` and, for the field and the
figures, from the ``Exploration``; nothing here runs the model.
"""
from __future__ import annotations

import platform
from pathlib import Path

import numpy as np

from geoback import __version__
from geoback.outputs import write_atomic, write_csv, write_json, write_matrix_csv
from geoback.reports.resultsets import result_set
from geoback.units import number, rounded, shown


def reading_label(lab, staged: bool = False) -> str:
    """instrument:station:component, and @stage when readings come from several construction stages."""
    survey = getattr(lab, "survey", None)
    return (f"{lab.instrument}:{lab.station}:{lab.component}" + (f"@{lab.stage}" if staged or survey else "")
            + (f"/{survey}" if survey else ""))


def several_stages(labels) -> bool:
    return len({lab.stage for lab in labels}) > 1


def summary(res, exploration=None, readings=()) -> dict:
    """summary.json: the estimate, its assessment and the run's counts; `readings`: how the readings
    were matched (observation.readings.CaseReadings.lines), one line per instrument."""
    f, rel, params = res.fit, res.reliability, res.parameters
    out = {
        "case": res.name,
        "case_hash": res.case_hash,
        "geoback_version": __version__,
        "status": res.status,
        "converged": f.status == "converged",
        "stop_reason": f.reason,
        "method": f.method,
        "weighting": res.weighting,
        "iterations": f.iterations,
        "parameters": {n: {"unit": params.units[i], "initial": params.initial[i], "estimate": f.p[i],
                           "std": rel.std[i], **res.interval(n).as_dict(),  # ci95 (None: ci95_reason), method, open
                           "at_bound": bool(f.at_bound[i]),
                           **(res.prior_posterior.as_dict(i) if res.prior_posterior is not None else {})}
                       for i, n in enumerate(params.names)},
        "warnings": [c.as_dict() for c in res.caveats],
        "mesh_error": ({**res.mesh_error.as_dict(), "included_in_C_x": res.mesh_error_included}
                       if res.mesh_error is not None else {"checked": False, "reason": "fit.mesh_error: ignore"}),
        "J": f.J, "chi2": rel.chi2, "dof": rel.dof, "reduced_chi2": rel.reduced_chi2, "p_value": rel.p_value,
        "minus_2_log_likelihood": rel.minus2logL, "aic": rel.aic, "bic": rel.bic,
        "condition_number": rel.condition, "undetermined": rel.undetermined,
        "error_scales": [e.as_dict() for e in rel.error_scales],
        "readings": res.data.m, **({"readings_matched": list(readings)} if readings else {}),
        "dofs": res.dofs, "elements": res.elements,
        **res.counts, "solver": res.solver,
        "timings_s": {k: round(v, 4) for k, v in res.seconds.items()},
        "platform": platform.platform(),
    }
    if rel.parameter_dof is not None:  # estimated error scales: t intervals and the F ellipse
        for i, n in enumerate(params.names):
            out["parameters"][n]["dof"] = rel.parameter_dof[i]
        out["ellipse_dof"] = rel.ellipse_dof
        out["ellipse_limit_95"] = rel.ellipse_limit(0.95)
    zone = getattr(exploration, "plastic_zone", None)
    if zone is not None:
        out["plastic_zone"] = zone.as_dict()
    if getattr(exploration, "triggers", None):
        from geoback.reports.update_report import triggers_json

        out["triggers"] = triggers_json(exploration.triggers)
    if getattr(exploration, "walls", None) is not None:
        from geoback.reports.walls import as_dict as walls_dict

        out["walls"] = walls_dict(exploration.walls)
    if getattr(exploration, "trough", None) is not None:
        from geoback.reports.trough import trough_dict

        out["trough"] = trough_dict(exploration.trough)
    if getattr(exploration, "damage", None) is not None:
        from geoback.reports.trough import damage_dict

        out["damage"] = damage_dict(exploration.damage)
    if res.forecasts is not None:
        from geoback.reports.forecast_report import as_dict

        out["forecasts"] = as_dict(res.forecasts)
    if exploration is not None:  # the work of the field file and figures, apart from the identification's
        out["exploration"] = {k: exploration.counts.get(k, 0) for k in ("factorisations", "solves", "forward_runs")}
        if getattr(exploration, "slice", None) is not None:  # the figures' objective map: the model's or linearised
            out["exploration"]["objective_map"] = exploration.slice.source
        out["timings_s"]["exploration"] = round(exploration.seconds, 4)
    return out


def _cv(value: float, std: float) -> str:
    if value == 0 or not np.isfinite(std):
        return ""
    return f" ({100 * std / abs(value):.0f} %)" if std / abs(value) >= 0.01 else f" ({100 * std / abs(value):.2g} %)"


def report_text(res, exploration=None, readings=(), figures=()) -> str:
    """A report in the spirit of lmfit's fit_report, warnings first, then the model fitted
    (``model.py``) and the fit; the plastic zone at the estimate when the exploration holds it;
    `readings`: how the readings were matched, one line per instrument
    (observation.readings.CaseReadings.lines); `figures`: the names of the figures the run wrote
    (``plots.plot_run``), each linked (as its PNG) under "## Figures"."""
    f, rel, params = res.fit, res.reliability, res.parameters
    lines = [f"# geoback fit report: {res.name}", ""]
    if res.caveats:
        lines += ["**Warnings**", ""] + [f"- [{c.code}] {c.message}" for c in res.caveats] + [""]
    from geoback.reports.model import model_section

    lines += model_section(res) + ["## The fit", ""]
    lines += [f"- status: **{res.status}** ({f.reason})",
              f"- method: {f.method}, {f.iterations} iterations, {res.counts['factorisations']} factorisation(s), "
              f"{res.counts['solves']} solves",
              f"- readings m = {res.data.m}, parameters n = {params.n}, dofs = {res.dofs}",
              *[f"  - {line}" for line in readings],
              chi2_line(rel),
              f"- AIC = {rel.aic:.6g}, BIC = {rel.bic:.6g}, condition number = {rel.condition:.3g}", "",
              "| parameter | unit | initial | estimate | std | 95 % interval |", "|---|---|---|---|---|---|"]
    case_units = []
    for i, n in enumerate(params.names):
        fct, unit = shown(params.units[i], f.p[i])
        bound = " (at bound)" if f.at_bound[i] else ""
        iv = res.interval(n)
        how = "" if iv.method == "linearised" else f" ({iv.method})"
        if iv.exists:
            lo_open, hi_open = iv.open
            ends = (f"≤ its bound {number(iv.low * fct)}" if lo_open else number(iv.low * fct),
                    f"≥ its bound {number(iv.high * fct)}" if hi_open else number(iv.high * fct))
            cell = f"[{ends[0]}, {ends[1]}]{how}"
        else:
            cell = f"none: {iv.reason}"
        lines.append(f"| {n} | {unit} | {number(params.initial[i] * fct)} | {number(f.p[i] * fct)}{bound} | "
                     f"{number(rel.std[i] * fct, 3)}{_cv(f.p[i], rel.std[i])} | {cell} |")
        if fct != 1.0:
            case_units.append(f"{n} = {f.p[i]:.6g} ± {number(rel.std[i], 3)} {params.units[i]}")
    if case_units:
        lines += ["", "In the case's units (as `parameters:` and summary.json take them): " + ", ".join(case_units)
                  + "."]
    lines += prior_posterior_lines(res)
    if rel.parameter_dof is not None:
        lines += ["", "The error scales are estimated: the intervals are Student t on "
                  + ", ".join(f"{n} {d:.3g}" for n, d in zip(params.names, rel.parameter_dof))
                  + f" degrees of freedom (Satterthwaite), the 95 % ellipse d² < {rel.ellipse_limit(0.95):.3g} "
                    f"(n F(n, {rel.ellipse_dof:.3g}))."]
    lines += error_scale_lines(rel)
    if rel.scales_estimated and res.weighting != "full":
        lines += ["", f"(weighting '{res.weighting}': the error scales multiply the weighting's covariance "
                      f"({'I, 1 m² per reading' if res.weighting == 'identity' else 'the diagonal of C_x'}), "
                      "not the stated C_x.)"]
    strong = [(params.names[i], params.names[j], rel.correlation[i, j])
              for i in range(params.n) for j in range(i + 1, params.n)
              if np.isfinite(rel.correlation[i, j]) and abs(rel.correlation[i, j]) > 0.5]
    if strong:
        lines += ["", "Correlations above 0.5: " + ", ".join(f"C({a}, {b}) = {c:+.3f}" for a, b, c in strong)]
    if res.mesh_error is not None:
        lines += ["", "Mesh: " + res.mesh_error.text() + (" - included in C_x for this fit"
                                                           if res.mesh_error_included else "")]
    top = np.argsort(-rel.leverage)[:3]
    lines += ["", "Most informative readings (leverage = diag Q): " +
              ", ".join(f"{reading_label(res.data.labels[i], several_stages(res.data.labels))} "
                        f"({rel.leverage[i]:.2f})" for i in top)]
    zone = getattr(exploration, "plastic_zone", None)
    if zone is not None:
        lines += zone.lines()
    lines += figure_lines(res, exploration, figures)
    text = "\n".join(lines) + "\n"
    if getattr(exploration, "walls", None) is not None:
        from geoback.reports.walls import report_section as walls_section

        text += walls_section(exploration.walls)
    if getattr(exploration, "trough", None) is not None or getattr(exploration, "damage", None) is not None:
        from geoback.reports.trough import damage_section, trough_section

        text += trough_section(getattr(exploration, "trough", None)) + damage_section(getattr(exploration, "damage",
                                                                                                     None))
    if res.forecasts is not None:
        from geoback.reports.forecast_report import report_section

        text += report_section(res.forecasts)
    if getattr(exploration, "triggers", None):
        from geoback.reports.update_report import trigger_section

        text += trigger_section(exploration.triggers)
    return text


def figure_lines(res, exploration, figures=()) -> list[str]:
    """"## Figures": every figure the run wrote (`figures`: their names, as ``plots.plot_run`` wrote
    them), linked as its PNG under a caption (``plots.caption``); what the objective map shows (the
    model's own or linearised) and why a path is missing."""
    slc = getattr(exploration, "slice", None)
    if slc is None and not figures:
        return []
    out = ["", "## Figures"]
    if slc is not None:
        from geoback.inference.explore import other_method
        from geoback.reports.plots.common import METHOD_NAMES

        out += ["", f"The objective map (objective_contours.png) shows {slc.words()}."]
        note = getattr(exploration, "other_note", "")
        if exploration.other is None and note:
            out.append(f"{METHOD_NAMES.get(other_method(res.fit.method), 'The other method')} {note}.")
    if figures:
        from geoback.reports.plots import caption

        for k, name in enumerate(figures, 1):
            out += ["", f"**Figure {k}.** {caption(name)} ({name}.png; vector graphics: {name}.svg).", "",
                    f"![Figure {k}: {caption(name)}]({name}.png)"]
    return out


def prior_posterior_lines(res) -> list[str]:
    """Prior -> posterior std of each parameter and its identifiability (identifiability.py)."""
    pp = res.prior_posterior
    if pp is None:
        return []
    out = ["", "What the readings tell (prior → posterior std; identifiability 0: nothing beyond the prior, "
               "1: fixed by the readings):", "",
           "| parameter | unit | prior std | prior | posterior std | reduction [%] | identifiability [-] |",
           "|---|---|---|---|---|---|---|"]
    units = res.parameters.units
    for i, n in enumerate(pp.names):
        fct, unit = shown(units[i], res.fit.p[i])
        out.append(f"| {n} | {unit} | {number(pp.prior_std[i] * fct, 3)} | {pp.prior_source[i]} | "
                   f"{number(pp.posterior_std[i] * fct, 3)} | {100 * pp.reduction[i]:.0f} | {pp.identifiability[i]:.2f} |")
    if "usual range" in pp.prior_source:
        out += ["", "(usual range: no prior in the case, so an uninformed one spanning the usual range for ground "
                    "as its 95 % interval, in ln p for positive quantities.)"]
    return out


def chi2_line(rel) -> str:
    if not rel.scales_estimated:
        return (f"- chi-square = {rel.chi2:.6g}, dof = {rel.dof}, reduced chi-square = {rel.reduced_chi2:.4g}, "
                f"p-value = {rel.p_value:.3g}")
    if rel.dof <= 0:
        return "- chi-square: every reading's scale is estimated, so no χ² test of the stated σ's (see the error scales)"
    return (f"- chi-square of the readings whose σ is known (and of the priors) = {rel.chi2:.6g}, dof = {rel.dof:.4g}, "
            f"reduced chi-square = {rel.reduced_chi2:.4g}, p-value = {rel.p_value:.3g} (Satterthwaite)")


READINGS_HEADER = ["instrument", "kind", "station", "stage", "component", "x [m]", "y [m]", "measured [mm]",
                   "computed [mm]", "residual [mm]", "whitened_residual [-]", "leverage [-]"]
ERROR_SCALE_HEADER = ["group", "instruments", "treatment", "readings", "dof", "k", "k_low95", "k_high95",
                      "k_readings", "p_stated", "p_allowed", "allowed_test", "ratio_to_others", "J_stated", "text"]


def error_scale_rows(rel) -> list[list]:
    return [[e.name, " ".join(e.instruments), e.treatment, e.readings, e.dof, e.factor, e.low, e.high,
             e.readings_factor, e.p_stated, e.p_allowed, e.allowed_test, e.ratio_to_others, e.J, e.text]
            for e in rel.error_scales]


def error_scale_lines(rel) -> list[str]:
    """The error-scale table of the report: k = true σ / stated σ of each instrument or group."""
    if not rel.error_scales:
        return []
    out = ["", "Error scales (k = true σ / stated σ; c = readings minus the parameters' share):", "",
           "| group | treatment | readings [-] | c [-] | k [-] | 95 % interval of k [-] | p (stated σ) [-] |",
           "|---|---|---|---|---|---|---|"]
    for e in rel.error_scales:
        k = f"{e.factor:.3g}" if e.estimated else f"1 (readings: {e.readings_factor:.3g})"
        out.append(f"| {e.name} | {e.treatment} | {e.readings} | {e.dof:.3g} | {k} | [{e.low:.3g}, {e.high:.3g}] | "
                   f"{e.p_stated:.2g} |")
    out += [""] + [f"- {e.text}" for e in rel.error_scales]
    return out


def write_field(field, path: Path, case=None) -> None:
    """Displacement (point data) and cell data (stresses, ...) as VTU for ParaView; more point data
    (the displacement after every construction stage) if the field has it. With `case` (a section
    with openings), each element's state after every stage as cell data 'state[<stage>]': -1
    excavated, 0 ground, 1 + i the lining or wall i of the mesh's bands standing there (threshold at >= 0
    in ParaView to see the section as it stands after that stage); with retaining walls, 'wall': 1 + the
    wall's index in construction.walls on its elements, 0 elsewhere (threshold at >= 1 to see the walls)."""
    from geoback.reports.fields import write_mesh

    def vec(v):
        v = np.asarray(v)
        return np.column_stack([v, np.zeros(len(v))]) if v.ndim == 2 and v.shape[1] == 2 else v

    point = {"displacement": vec(field.displacement)}
    point.update({k: vec(v) for k, v in getattr(field, "point_data", {}).items()})
    cells = dict(field.cell_data)
    if case is not None and getattr(field.mesh, "part", None) is not None:
        from geoback.reports.section import has_openings, stage_names, stage_state

        if has_openings(case):
            for k, stage in enumerate(stage_names(case)):
                void, lining = stage_state(case, field.mesh, k)
                cells[f"state[{stage}]"] = np.where(void, -1, lining + 1).astype(np.int32)
            from geoback.reports.section import wall_names

            walls = [i for i, n in enumerate(field.mesh.band_names) if n in wall_names(case)]
            if walls:  # the retaining walls' elements: 1 + the wall's index in construction.walls, 0 elsewhere
                order = wall_names(case)
                mark = np.zeros(len(field.mesh.triangles), np.int32)
                for i in walls:
                    mark[field.mesh.band == i] = 1 + order.index(field.mesh.band_names[i])
                cells["wall"] = mark
    write_mesh(field.mesh, path, point_data=point, cell_data=cells)


def write_run(res, out: Path, exploration=None, plots: bool = False, readings=()) -> None:
    """Every file of a run, replacing the previous run's set in `out` as a whole (outputs.result_set);
    the field (field.vtu) and figures if the exploration has them; `readings`: how the readings were
    matched, in report.md and summary.json."""
    with result_set(out, "run") as staging:
        _write_run(res, staging, exploration, plots, readings)


def _write_run(res, out: Path, exploration, plots: bool, readings=()) -> None:
    f, rel, params = res.fit, res.reliability, res.parameters
    names = params.names
    out = Path(out)
    lo, hi = res.intervals95()
    pp = res.prior_posterior
    shown_as = [shown(params.units[i], f.p[i]) for i in range(params.n)]
    write_csv(out / "parameters.csv",
              ["name", "unit", "initial", "estimate", "std", "ci95_low", "ci95_high", "ci95_method", "at_bound",
               "prior_std", "prior_source", "posterior_std", "identifiability",
               "unit_shown", "estimate_shown", "std_shown", "ci95_low_shown", "ci95_high_shown"],
              [[n, params.units[i], params.initial[i], f.p[i], rel.std[i], lo[i], hi[i],
                res.interval(n).method, bool(f.at_bound[i])]
               + ([pp.prior_std[i], pp.prior_source[i], pp.posterior_std[i], pp.identifiability[i]] if pp is not None
                  else ["", "", "", ""])
               + [shown_as[i][1]] + [rounded(v * shown_as[i][0]) for v in (f.p[i], rel.std[i], lo[i], hi[i])]
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
    dated = any(getattr(lab, "survey", None) for lab in res.data.labels)  # a survey column after the stage
    header = READINGS_HEADER[:4] + ["survey"] + READINGS_HEADER[4:] if dated else READINGS_HEADER
    write_csv(out / "readings.csv", header,
              [[lab.instrument, lab.kind, lab.station, lab.stage or ""] + ([lab.survey or ""] if dated else [])
               + [lab.component, rounded(lab.x), rounded(lab.y),
                  rounded(1e3 * measured[i]), rounded(1e3 * f.x[i]), rounded(1e3 * residual[i]),
                  rounded(rel.whitened_residual[i]), rounded(rel.leverage[i])] for i, lab in enumerate(res.data.labels)])
    write_csv(out / "error_scales.csv", ERROR_SCALE_HEADER, error_scale_rows(rel))
    write_csv(out / "iterations.csv", ["iteration", "mu", "J"] + names + ["accepted"],
              [[h.k, h.mu, h.J] + list(h.p) + [h.accepted] for h in f.history])
    if exploration is not None and exploration.field is not None:
        write_field(exploration.field, out / "field.vtu", res.case)
    if exploration is not None and getattr(exploration, "lining", None) is not None:
        from geoback.reports.fields import write_lining

        write_lining(exploration.lining, out, vtu=exploration.field is not None)
    if exploration is not None and getattr(exploration, "plastic_zone", None) is not None:
        from geoback.reports.fields import write_plastic_zone

        write_plastic_zone(exploration.plastic_zone, out)
    if exploration is not None and getattr(exploration, "walls", None) is not None:
        from geoback.reports.walls import write_walls

        write_walls(exploration.walls, out)
    if exploration is not None and getattr(exploration, "trough", None) is not None:
        from geoback.reports.trough import write_trough

        write_trough(exploration.trough, out)
    if exploration is not None and getattr(exploration, "damage", None) is not None:
        from geoback.reports.trough import write_damage

        write_damage(exploration.damage, out)
    if res.forecasts is not None:
        from geoback.reports.forecast_report import HEADER, forecast_rows

        write_csv(out / "forecast.csv", HEADER, forecast_rows(res.forecasts))
    if exploration is not None and getattr(exploration, "triggers", None):
        from geoback.reports.update_report import TRIGGER_HEADER, trigger_row

        write_csv(out / "triggers.csv", TRIGGER_HEADER[1:], [trigger_row(t)[1:] for t in exploration.triggers])
    figures = []
    if plots:
        from geoback.reports.plots import plot_run

        figures = list(dict.fromkeys(p.stem for p in plot_run(res, exploration, out)))
    text = report_text(res, exploration, readings, figures)
    write_atomic(out / "report.md", text)
    from geoback.reports.html import write_html

    write_html(out / "report.html", text, out, res)
    write_json(out / "summary.json", summary(res, exploration, readings))
