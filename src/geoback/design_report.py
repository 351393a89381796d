"""`geoback design` as files and words: design.csv, design.md, design.json (readers only)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .forecast_report import SHOW
from .outputs import write_atomic, write_csv, write_json


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
    lines += ["", "Now: " + ", ".join(f"std {n} = {s:.3g}" for n, s in zip(d.parameters, d.std_before)) + ".",
              "", "Every candidate and target point: design.csv."]
    return "\n".join(lines) + "\n"


def design_rows(d) -> tuple[list[str], list[list]]:
    header = ["candidate", "kind", "stage", "readings", "varied_field", "varied_value", "objective", "before",
              "after", "reduction", "rank"] + [f"std_after_{n}" for n in d.parameters] + \
        [f"target_std_after:{lab}" for lab in d.target_rows]
    rank = np.empty(len(d.names), int)
    rank[d.ranking] = np.arange(1, len(d.names) + 1)
    rows = [[d.names[k], d.kinds[k], d.stages[k], d.readings[k], d.varied[k][0] if d.varied[k] else "",
             d.varied[k][1] if d.varied[k] else "", d.objective, d.before, d.after[k], d.reduction[k], rank[k]]
            + list(d.std_after[k]) + (list(d.target_after[k]) if len(d.target_rows) else [])
            for k in range(len(d.names))]
    return header, rows


def write_design(d, out: Path, case_name: str, plots: bool = True) -> None:
    from .resultsets import result_set

    with result_set(Path(out), "design") as staging:
        header, rows = design_rows(d)
        write_csv(staging / "design.csv", header, rows)
        write_atomic(staging / "design.md", design_text(d, case_name))
        write_json(staging / "design.json", {
            "objective": d.objective, "targets": d.targets, "best": d.best, "before": d.before,
            "candidates": {d.names[k]: {"kind": d.kinds[k], "stage": d.stages[k], "after": float(d.after[k]),
                                        "reduction": float(d.reduction[k])} for k in range(len(d.names))},
            "counts": {k: d.counts.get(k, 0) for k in ("factorisations", "solves", "forward_runs")},
            "seconds": round(d.seconds, 4)})
        if plots:
            import matplotlib

            from .plots import save_figures
            from .plots.common import RC
            from .plots.design import design_figure

            with matplotlib.rc_context(RC):
                fig = design_figure(d)
            save_figures({"design": fig}, staging)
