"""`geoback update`'s files: the history of every parameter (history.csv), every forecast of a later
survey and how it scored when read (forecasts_ahead.csv, forecast_checks.csv), the trigger levels
(triggers.csv), report.md, summary.json and, with plots, history.png and forecast_checks.png."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from geoback.case.dates import RULE, shown_date, stage_periods
from geoback.outputs import write_atomic, write_csv, write_json
from geoback.reports.resultsets import result_set
from geoback.units import number, rounded, shown
from geoback.worth.updating import Z95

HISTORY_HEADER = ["fitted_through", "surveys", "parameter", "unit", "estimate", "std", "ci95_low", "ci95_high",
                  "unit_shown", "estimate_shown", "ci95_low_shown", "ci95_high_shown", "status", "chi2", "readings"]
CHECK_HEADER = ["forecast_by", "stage", "survey", "instrument", "station", "component", "x [m]", "y [m]",
                "forecast", "std_model", "std_reading", "band95_low", "band95_high", "measured", "unit", "z [-]",
                "inside_95"]
AHEAD_HEADER = ["forecast_by", "stage", "instrument", "station", "component", "x [m]", "y [m]", "forecast",
                "std_model", "band95_low", "band95_high", "unit"]
TRIGGER_HEADER = ["fitted_through", "quantity", "when", "stage", "where", "value", "std", "amber", "red",
                  "p_amber", "p_red", "p_amber_sampled", "p_red_sampled", "unit", "status"]


def _scale(kind: str) -> tuple[float, str]:
    return (1.0, "kN") if kind == "load_cell" else (1e3, "mm")


def history_rows(steps) -> list[list]:
    rows = []
    for s in steps:
        res = s.result
        lo, hi = res.intervals95()
        p = res.parameters
        chi2 = float(res.reliability.chi2)
        for i, n in enumerate(p.names):
            f, u = shown(p.units[i], res.fit.p[i])
            rows.append([s.stage, len(s.surveys), n, p.units[i], res.fit.p[i], res.reliability.std[i], lo[i], hi[i],
                         u, rounded(f * res.fit.p[i]), rounded(f * lo[i]), rounded(f * hi[i]), res.status, chi2,
                         len(res.data.measured)])
    return rows


def check_rows(steps) -> list[list]:
    rows = []
    for s in steps:
        for c in s.checks:
            f, unit = _scale(c.kind)
            z, sr = c.z, c.std_reading
            for i, lab in enumerate(c.labels):
                rows.append([c.fitted, c.stage, c.survey or "", c.instrument, lab.station, lab.component,
                             rounded(lab.x), rounded(lab.y), rounded(f * c.forecast[i]), rounded(f * c.std_model[i]),
                             rounded(f * sr[i]), rounded(f * (c.forecast[i] - Z95 * sr[i])),
                             rounded(f * (c.forecast[i] + Z95 * sr[i])), rounded(f * c.measured[i]), unit,
                             rounded(z[i]), bool(abs(z[i]) <= Z95)])
    return rows


def ahead_rows(steps) -> list[list]:
    rows = []
    for s in steps:
        for a in s.ahead:
            f, unit = _scale(a.kind)
            sd = a.std_model
            for i, lab in enumerate(a.labels):
                rows.append([s.stage, a.stage, a.instrument, lab.station, lab.component, rounded(lab.x),
                             rounded(lab.y), rounded(f * a.forecast[i]), rounded(f * sd[i]),
                             rounded(f * (a.forecast[i] - Z95 * sd[i])), rounded(f * (a.forecast[i] + Z95 * sd[i])),
                             unit])
    return rows


def _level_scale(unit: str) -> tuple[float, str]:
    return (1e3, "mm") if unit == "m" else (1.0, unit)


def trigger_row(t, fitted: str = "") -> list:
    """One TriggerRow as a row of TRIGGER_HEADER (levels and values in mm or kN)."""
    f, unit = _level_scale(t.unit)
    return [fitted, t.quantity, t.when, t.stage, t.where, rounded(f * t.value, 6), rounded(f * t.std, 6),
            "" if t.amber is None else rounded(f * t.amber, 6), "" if t.red is None else rounded(f * t.red, 6),
            rounded(t.p_amber, 6), rounded(t.p_red, 6), "" if t.p_amber_sampled != t.p_amber_sampled else
            rounded(t.p_amber_sampled, 6), "" if t.p_red_sampled != t.p_red_sampled else rounded(t.p_red_sampled, 6),
            unit, t.status]


def trigger_table_rows(steps) -> list[list]:
    return [trigger_row(t, s.stage) for s in steps for t in s.triggers]


def triggers_json(triggers) -> list[dict]:
    return [{"quantity": t.quantity, "when": t.when, "stage": t.stage, "where": t.where, "value": t.value,
             "std": t.std, "amber": t.amber, "red": t.red, "p_amber": t.p_amber, "p_red": t.p_red,
             "p_amber_sampled": None if t.p_amber_sampled != t.p_amber_sampled else t.p_amber_sampled,
             "p_red_sampled": None if t.p_red_sampled != t.p_red_sampled else t.p_red_sampled,
             "unit": t.unit, "status": t.status, "nonlinear": t.nonlinear} for t in triggers]


TRIGGER_WORDS = ("the probability that the movement exceeds each level at the next stage and at the end (first order, "
                 "from the band of the model's movement, and for a forecast also from the sampling check's draws "
                 "through the model; the reading most likely to exceed red is shown). Status (from the sampled "
                 "probabilities where the sampled band departs from the linear one): "
                 "red when red is more likely than not, amber when amber is more likely than not or red has 5 % "
                 "or more, else green.")


def trigger_section(triggers) -> str:
    """The TARP section of a run's report.md."""
    lines = ["", "## Trigger levels (TARP)", "",
             f"The latest survey against the levels, and {TRIGGER_WORDS} Every row: triggers.csv.", ""]
    lines += trigger_lines(triggers)
    odd = [t.quantity for t in triggers if t.nonlinear]
    if odd:
        lines += ["", f"The sampled band of {', '.join(odd)} departs from the linear one (the model is non-linear "
                      f"there): its status is read from the probabilities sampled through the model."]
    return "\n".join(lines) + "\n"


def _pct(p: float) -> str:
    if p != p:
        return "-"
    if p < 0.001:
        return "< 0.1 %"
    if p > 0.999:
        return "> 99.9 %"
    return f"{100 * p:.1f} %"


def _sampled(p: float) -> str:
    return "" if p != p else f" (sampled {_pct(p)})"


def trigger_lines(triggers) -> list[str]:
    """The TARP status table of one step, in Markdown."""
    if not triggers:
        return []
    out = ["| quantity | when | stage | where | value | amber | red | P(> amber) | P(> red) | status |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for t in triggers:
        f, unit = _level_scale(t.unit)
        value = f"{number(f * t.value, 3)} {unit}" + ("" if t.measured else f" ± {number(Z95 * f * t.std, 2)}")
        lv = (lambda v: "-" if v is None else f"{number(f * v, 3)} {unit}")
        pa = "-" if t.measured else _pct(t.p_amber) + _sampled(t.p_amber_sampled)
        pr = "-" if t.measured else _pct(t.p_red) + _sampled(t.p_red_sampled)
        out.append(f"| {t.quantity} | {t.when} | {t.stage} | {t.where} | {value} | {lv(t.amber)} | {lv(t.red)} | "
                   f"{pa} | {pr} | **{t.status}** |")
    return out


def update_text(steps, loaded, until) -> str:
    case = loaded.case
    last = steps[-1]
    cut = "every survey" if until is None else (f"the surveys up to stage '{until}'" if isinstance(until, str)
                                               else f"the surveys up to {shown_date(until)}")
    lines = [f"# {case.name}: update as construction proceeds", "",
             f"Fitted stage by stage with {cut}: at each stage a joint refit of every survey read by its end (so the "
             f"last step is the fit of all surveys), a forecast of every instrument at every later stage with its "
             f"95 % band, and the surveys of each stage scored against the forecast made before they were read "
             f"(the band of a reading: the model's band from C_p plus the reading's own error C_x).", ""]
    if stage_periods(case) is not None:
        lines += [f"Surveys and stages: {RULE}.", ""]
    lines += ["## Parameters stage by stage", "", "| fitted through | surveys | " +
              " | ".join(last.result.parameters.names) + " |", "|---|---|" + "---|" * len(last.result.parameters.names)]
    for s in steps:
        res = s.result
        lo, hi = res.intervals95()
        cells = []
        for i, n in enumerate(res.parameters.names):
            f, u = shown(res.parameters.units[i], res.fit.p[i])
            u = "" if u in ("-", "") else f" {u}"
            cells.append(f"{number(f * res.fit.p[i], 4)}{u} [{number(f * lo[i], 3)}, {number(f * hi[i], 3)}]")
        lines.append(f"| {s.stage} | {len(s.surveys)} | " + " | ".join(cells) + " |")
    lines += ["", "Every step's estimate, std and 95 % interval: history.csv (and history.png with --plots).", ""]
    seq = [s for s in steps if s.sequential is not None]
    if seq:
        worst = max(float(np.max(np.abs(s.sequential.difference_std))) for s in seq)
        lines += [f"Check: the sequential Bayesian update (each step's posterior, linearised, as the prior of the next "
                  f"step's new surveys alone) ends {worst:.2g} σ or less from the joint refit at every step "
                  f"({', '.join(f'{n} {d:+.2g} σ' for n, d in zip(last.result.parameters.names, seq[-1].sequential.difference_std))} "
                  f"at the last). They are the same for a model linear in its parameters; the difference is the "
                  f"curvature the linearisation leaves out, and the joint refit, which has none of it, is reported.",
                  ""]
    checked = [c for s in steps for c in s.checks]
    lines += ["## Each stage's surveys against the previous forecast", ""]
    if not checked:
        lines += ["No survey of a later stage has been read yet: nothing to score.", ""]
    for c in checked:
        lines.append(f"- {c.sentence()}")
    if checked:
        inside = sum(c.inside for c in checked)
        total = sum(len(c.z) for c in checked)
        lines += ["", f"In all, {inside} of {total} readings fell inside the 95 % band forecast before they were read "
                      f"({100 * inside / total:.0f} %; about 95 % are expected when the model and the stated errors "
                      f"hold). Every reading: forecast_checks.csv.", ""]
    if last.triggers:
        lines += ["## Trigger levels (TARP)", "",
                  f"After the fit through stage '{last.stage}': the latest survey against the levels, and "
                  f"{TRIGGER_WORDS}", ""]
        lines += trigger_lines(last.triggers) + ["", "Every step: triggers.csv.", ""]
    later = [a for a in last.ahead]
    if later:
        lines += ["## Forecast of the later stages", "",
                  f"From the fit through stage '{last.stage}', every instrument at every later stage with its 95 % "
                  f"band (forecasts_ahead.csv):", ""]
        for a in later:
            f, unit = _scale(a.kind)
            i = int(np.argmax(np.abs(a.forecast)))
            lines.append(f"- {a.instrument} at stage {a.stage}: largest {f * a.forecast[i]:.3g} ± "
                         f"{Z95 * f * a.std_model[i]:.2g} {unit} ({a.labels[i].component}, station {a.labels[i].station})")
        lines.append("")
    caveats = [c for s in steps[-1:] for c in s.result.caveats]
    if caveats:
        lines += ["## Warnings", ""] + [f"- {c.message}" for c in caveats] + [""]
    return "\n".join(lines)


def update_summary(steps, until) -> dict:
    last = steps[-1]
    return {
        "until": None if until is None else (until if isinstance(until, str) else shown_date(until)),
        "steps": [{"fitted_through": s.stage, "surveys": list(s.surveys), "status": s.result.status,
                   "sequential_minus_joint_std": None if s.sequential is None else
                   dict(zip(s.result.parameters.names, map(float, s.sequential.difference_std))),
                   "parameters": {n: {"estimate": float(s.result.fit.p[i]), "std": float(s.result.reliability.std[i])}
                                  for i, n in enumerate(s.result.parameters.names)},
                   "checks": [{"stage": c.stage, "survey": c.survey, "instrument": c.instrument, "chi2": c.chi2,
                               "dof": len(c.z), "p": c.p, "inside_95": c.inside, "max_abs_z": float(np.max(np.abs(c.z))),
                               "text": c.sentence()} for c in s.checks]} for s in steps],
        "triggers": triggers_json(last.triggers),
        "status": max((t.status for t in last.triggers), key=("green", "amber", "red").index, default="green"),
    }


def write_update(steps, loaded, out: Path, until, plots: bool = False) -> None:
    with result_set(out, "update") as staging:
        write_csv(staging / "history.csv", HISTORY_HEADER, history_rows(steps))
        write_csv(staging / "forecast_checks.csv", CHECK_HEADER, check_rows(steps))
        write_csv(staging / "forecasts_ahead.csv", AHEAD_HEADER, ahead_rows(steps))
        write_csv(staging / "triggers.csv", TRIGGER_HEADER, trigger_table_rows(steps))
        text = update_text(steps, loaded, until)
        if plots:
            from geoback.reports.plots import save_figures
            from geoback.reports.plots.update import checks_figure, history_figure

            figs = {"history": history_figure(steps, loaded.case.name),
                    "forecast_checks": checks_figure(steps, loaded.case.name)}
            save_figures({k: v for k, v in figs.items() if v is not None}, staging)
            text += "\n## Figures\n\n" + "\n\n".join(f"![{k.replace('_', ' ')}]({k}.png)" for k, v in figs.items()
                                                     if v is not None) + "\n"
        write_atomic(staging / "report.md", text)
        from geoback.reports.html import write_html

        write_html(staging / "report.html", text, staging, None, name=loaded.case.name,  # warnings: their section
                   kind="update as construction proceeds",
                   how_to_read="Read the parameters stage by stage first, then how each stage's surveys scored "
                               "against the forecast made before they were read (inside the 95 % band about 95 % "
                               "of the time when the model and the stated errors hold), then the trigger table: "
                               "the status now and the probability that each level is exceeded at the next stage "
                               "and at the end.")
        write_json(staging / "summary.json", update_summary(steps, until))
