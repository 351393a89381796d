"""diagnosis.md / diagnosis.json: what was wrong, where, what was missing, how much better it fits."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..outputs import write_atomic, write_json
from ..resultsets import result_set


def _fit_line(chi2: float, dof: float, p: float) -> str:
    if not dof > 0:
        return "no χ² test of stated σ's: every reading's error scale is estimated"
    shown = dof if isinstance(dof, (int, np.integer)) else f"{dof:.4g}"
    return f"χ² = {chi2:.4g} on {shown} dof (χ²/dof = {chi2 / dof if dof else float('nan'):.3g}, p = {p:.3g})"


def _scale_failures(rnd) -> list:
    return [e for e in rnd.scales if e.estimated and e.allowed_test and e.p_allowed < rnd.scale_threshold]


def _scale_lines(rnd) -> list[str]:
    """The estimated error scales of a round and whether each is within what the case allows."""
    est = [e for e in rnd.scales if e.estimated]
    if not est:
        return []
    out = [f"- error scales estimated (tested at {rnd.scale_threshold:.2g} each, Bonferroni):"]
    for e in est:
        flag = " **beyond what the case allows**" if e in _scale_failures(rnd) else ""
        out.append(f"  - {e.text}{flag}")
    return out


def _estimates(s) -> list[tuple[str, float, float, float, float]]:
    rel, f = s.reliability, s.refit
    lo, hi = rel.interval95()
    out = []
    for name in s.hypothesis.names:
        i = rel.names.index(name)
        out.append((name, f.p[i], rel.std[i], lo[i], hi[i]))
    return out


def verdict(d) -> str:
    """The plain-words answer."""
    b = d.baseline_reliability
    failing = _scale_failures(d.rounds[0])
    if failing and not d.accepted:
        return ("The model does not explain the readings within the errors the case allows: "
                + "; ".join(e.text for e in failing)
                + f". None of the hypotheses in the library improves the fit significantly "
                  f"({_fit_line(b.chi2, b.dof, b.p_value)}). Check those readings and their stated errors.")
    if d.adequate_before:
        scaled = (" (with the error scales the case lets geoback estimate, each within what the case allows)"
                  if any(e.estimated for e in d.rounds[0].scales) else "")
        best = next((s for s in d.rounds[0].ranking if s.collinear_with is None), None)
        extra = (f", and no hypothesis of the library improves it significantly (best: {best.hypothesis.title}, "
                 f"score-test p = {best.p_score:.2g} against the level {d.rounds[0].threshold:.2g})") if best else ""
        return (f"The model is adequate: {_fit_line(b.chi2, b.dof, b.p_value)}{extra} - the readings are explained "
                f"within their stated errors{scaled}. Nothing is missing.")
    if not d.accepted:
        return (f"The model does not explain the readings ({_fit_line(b.chi2, b.dof, b.p_value)}), but none of the "
                f"hypotheses in the library improves the fit significantly. Check the readings and their stated "
                f"errors, or the geometry.")
    parts = []
    for s in d.accepted:
        est = "; ".join(f"{n} = {v:.4g} ± {sd:.2g} (95 % [{lo:.4g}, {hi:.4g}])" for n, v, sd, lo, hi in _estimates(s))
        depth = ""
        if s.hypothesis.extra_values and s.hypothesis.kind != "layer-boundary":
            depth = " at " + ", ".join(f"{k} = {v:g} m" for k, v in s.hypothesis.extra_values.items())
        parts.append(f"{s.hypothesis.title}{depth}: {est}")
    f = d.final_reliability
    state = "adequate" if d.adequate_after else "still not adequate"
    return (f"Missing physics: {' + '.join(parts)}. Fit before: {_fit_line(b.chi2, b.dof, b.p_value)}; after: "
            f"{_fit_line(f.chi2, f.dof, f.p_value)} - {state}.")


def diagnosis_text(d) -> str:
    lines = [f"# geoback diagnosis: {d.case}", "", verdict(d), ""]
    for k, rnd in enumerate(d.rounds, 1):
        lines += [f"## Round {k}", "", f"- fit: {_fit_line(rnd.chi2, rnd.dof, rnd.p_value)}"] + _scale_lines(rnd)
        if rnd.adequate and rnd.accepted is None:
            scales = (", every estimated error scale is within what the case allows"
                      if any(e.estimated for e in rnd.scales) else "")
            lines += [f"- adequate: the χ² test passes at the {100 * d.alpha:g} % level{scales} and no hypothesis' "
                      f"score test is significant at {rnd.threshold:.2g} (= {d.alpha:g} / number of hypotheses); stop"]
        else:
            lines += ["- where the model and the readings differ:"] + [f"  - {m.text}" for m in rnd.mismatches[:4]]
        if rnd.ranking:
            lines += ["", "| hypothesis | score S | p (score) | ΔJ | p (LR) | AIC | BIC | estimate |",
                      "|---|---|---|---|---|---|---|---|"]
            for s in rnd.ranking:
                if s.collinear_with:
                    lines.append(f"| {s.hypothesis.title} | - | - | - | - | - | - | cannot be identified together "
                                 f"with {s.collinear_with}: same effect on the readings |")
                    continue
                est = ""
                if s.refit is not None:
                    est = "; ".join(f"{n} = {v:.4g} ± {sd:.2g}" for n, v, sd, _, _ in _estimates(s))
                    if s.hypothesis.extra_values:
                        est += " (" + ", ".join(f"{k2} = {v:g}" for k2, v in s.hypothesis.extra_values.items()) + ")"
                fmt = (lambda v: f"{v:.4g}" if np.isfinite(v) else "-")
                lines.append(f"| {s.hypothesis.title} | {fmt(s.score)} | {fmt(s.p_score)} | {fmt(s.dJ)} | "
                             f"{fmt(s.p_lr)} | {fmt(s.aic)} | {fmt(s.bic)} | {est} |")
        if rnd.accepted is not None:
            lines += ["", f"Accepted: **{rnd.accepted.hypothesis.title}** - {rnd.accepted.hypothesis.description}"]
        else:
            lines += ["", "No hypothesis is significant (likelihood-ratio test with Bonferroni correction)."]
        lines.append("")
    return "\n".join(lines) + "\n"


def diagnosis_json(d) -> dict:
    def scored(s):
        item = {"key": s.hypothesis.key, "kind": s.hypothesis.kind, "title": s.hypothesis.title,
                "description": s.hypothesis.description, "score": s.score, "score_dof": s.dof,
                "p_score": s.p_score, "collinear_with": s.collinear_with, "extra_values": s.hypothesis.extra_values}
        if s.refit is not None:
            item.update(dJ=s.dJ, p_lr=s.p_lr, aic=s.aic, bic=s.bic, status=s.refit.status,
                        estimates={n: {"estimate": v, "std": sd, "ci95": [lo, hi]}
                                   for n, v, sd, lo, hi in _estimates(s)})
        return item

    b, f = d.baseline_reliability, d.final_reliability
    return {
        "case": d.case, "alpha": d.alpha, "verdict": verdict(d),
        "adequate_before": d.adequate_before, "adequate_after": d.adequate_after,
        "before": {"chi2": b.chi2, "dof": b.dof, "reduced_chi2": b.reduced_chi2, "p_value": b.p_value,
                   "parameters": dict(zip(b.names, d.baseline_fit.p))},
        "after": {"chi2": f.chi2, "dof": f.dof, "reduced_chi2": f.reduced_chi2, "p_value": f.p_value,
                  "parameters": dict(zip(f.names, d.final_fit.p)), "std": dict(zip(f.names, f.std))},
        "missing": [scored(s) for s in d.accepted],
        "rounds": [{"chi2": r.chi2, "dof": r.dof, "p_value": r.p_value,
                    "error_scales": [e.as_dict() for e in r.scales if e.estimated],
                    "scale_threshold": r.scale_threshold,
                    "mismatches": [m.__dict__ for m in r.mismatches],
                    "ranking": [scored(s) for s in r.ranking],
                    "accepted": r.accepted.hypothesis.key if r.accepted else None} for r in d.rounds],
    }


def write_diagnosis(d, out: Path, plots: bool = True, exploration=None) -> None:
    """diagnosis.md, diagnosis.json and (plots) diagnosis.png/.svg, replacing the previous set in `out`
    as a whole; `exploration` gives the figure the model along each instrument at the final fit."""
    with result_set(out, "diagnose") as staging:
        write_atomic(staging / "diagnosis.md", diagnosis_text(d))
        write_json(staging / "diagnosis.json", diagnosis_json(d))
        if plots:
            from .figure import plot_before_after

            plot_before_after(d, staging, exploration)
