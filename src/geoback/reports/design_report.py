"""`geoback design` as files and words: design.csv, design.md, design.json (readers only)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from geoback.reports.forecast_report import SHOW
from geoback.outputs import write_atomic, write_csv, write_json


def _show(v: float, unit: str) -> str:
    f, u = SHOW.get(unit, (1.0, unit))
    return f"{v * f:.3g} {u}"


def _objective_words(d) -> str:
    if d.objective == "forecasts":
        return f"the root-mean-square std of the forecast{'s' if len(d.targets) > 1 else ''} {', '.join(d.targets)}"
    return "the volume of the parameters' 95 % confidence ellipsoid (ln det C_p)"


def design_text(d, case_name: str) -> str:
    order = d.ranking
    best = int(order[0])
    lines = [f"# geoback design: {case_name}", "",
             f"Candidates ranked by how much they would narrow {_objective_words(d)}, at the estimate, "
             "before any of them is installed (linearised, as C_p).", ""]
    if d.objective == "forecasts":
        lines += [f"Now: {_show(d.before, d.unit)}. Best: **{d.names[best]}** (read at stage {d.stages[best]}): "
                  f"{_show(d.after[best], d.unit)}, {100 * d.reduction[best]:.0f} % narrower.", ""]
    else:
        lines += [f"Best: **{d.names[best]}** (read at stage {d.stages[best]}): the ellipsoid's volume "
                  f"{100 * d.reduction[best]:.0f} % smaller.", ""]
    head = "| rank | candidate | kind | stage | readings | " + \
        ("rms std after | " if d.objective == "forecasts" else "") + "reduction | " + \
        " | ".join(f"std {n} after" for n in d.parameters) + " |"
    lines += [head, "|" + "---|" * (head.count("|") - 1)]
    for r, k in enumerate(order):
        cells = [str(r + 1), d.names[k], d.kinds[k], d.stages[k], str(d.readings[k])]
        if d.objective == "forecasts":
            cells.append(_show(d.after[k], d.unit))
        cells.append(f"{100 * d.reduction[k]:.1f} %")
        cells += [f"{d.std_after[k, j]:.3g}" for j in range(len(d.parameters))]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "Now: " + ", ".join(f"std {n} = {s:.3g}" for n, s in zip(d.parameters, d.std_before)) + "."]
    lines += separation_lines(d)
    lines += ["", "Every candidate and target point: design.csv."]
    return "\n".join(lines) + "\n"


def separation_lines(d) -> list[str]:
    """The candidates' power to tell the two leading hypotheses apart (`geoback design --separate`)."""
    D = d.discrimination
    if D is None:
        return []
    if not D.found:
        return ["", "## Telling hypotheses apart", "",
                "`geoback diagnose` refitted no hypothesis: the readings show nothing its library can detect "
                "that the case's model misses, so there is nothing to tell apart."]
    order = np.argsort(-D.separation, kind="stable")
    best = int(order[0])
    lines = ["", f"## Telling {D.a} from {D.b}", "",
             f"The two hypotheses `geoback diagnose` finds leading. λ: how much the wrong one's χ² would grow "
             f"once the candidate's readings join (refitted, linearised), whichever is true; power: the chance "
             f"that a test at {100 * D.level:.0f} % then rejects the wrong one.", ""]
    if D.separation[best] < 1e-9:
        lines.append("No candidate would tell them apart: both predict the same readings there.")
        return lines
    lines += [f"Best: **{D.names[best]}** (power {D.power[best]:.2f}).", "",
              "| rank | candidate | λ if the first is true | λ if the second is true | power |", "|---|---|---|---|---|"]
    for r, k in enumerate(order):
        lines.append(f"| {r + 1} | {D.names[k]} | {D.lam_ab[k]:.3g} | {D.lam_ba[k]:.3g} | {D.power[k]:.2f} |")
    return lines


def design_rows(d) -> tuple[list[str], list[list]]:
    header = ["candidate", "kind", "stage", "readings", "varied_field", "varied_value", "objective", "before",
              "after", "reduction", "rank"] + [f"std_after_{n}" for n in d.parameters] + \
        [f"target_std_after:{lab}" for lab in d.target_rows] + \
        (["separation", "separation_power"] if d.discrimination is not None and d.discrimination.found else [])
    rank = np.empty(len(d.names), int)
    rank[d.ranking] = np.arange(1, len(d.names) + 1)
    rows = [[d.names[k], d.kinds[k], d.stages[k], d.readings[k], d.varied[k][0] if d.varied[k] else "",
             d.varied[k][1] if d.varied[k] else "", d.objective, d.before, d.after[k], d.reduction[k], rank[k]]
            + list(d.std_after[k]) + (list(d.target_after[k]) if len(d.target_rows) else [])
            + ([d.discrimination.separation[k], d.discrimination.power[k]]
               if d.discrimination is not None and d.discrimination.found else [])
            for k in range(len(d.names))]
    return header, rows


def write_design(d, out: Path, case_name: str, plots: bool = True) -> None:
    from geoback.reports.resultsets import result_set

    with result_set(Path(out), "design") as staging:
        header, rows = design_rows(d)
        write_csv(staging / "design.csv", header, rows)
        write_atomic(staging / "design.md", design_text(d, case_name))
        write_json(staging / "design.json", {
            "objective": d.objective, "targets": d.targets, "best": d.best, "before": d.before,
            "candidates": {d.names[k]: {"kind": d.kinds[k], "stage": d.stages[k], "after": float(d.after[k]),
                                        "reduction": float(d.reduction[k])} for k in range(len(d.names))},
            "separation": None if d.discrimination is None else d.discrimination.as_dict(),
            "counts": {k: d.counts.get(k, 0) for k in ("factorisations", "solves", "forward_runs")},
            "seconds": round(d.seconds, 4)})
        if plots:
            import matplotlib

            from geoback.reports.plots import save_figures
            from geoback.reports.plots.common import RC
            from geoback.reports.plots.design import design_figure

            with matplotlib.rc_context(RC):
                fig = design_figure(d)
            save_figures({"design": fig}, staging)
