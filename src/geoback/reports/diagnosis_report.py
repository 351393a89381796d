"""diagnosis.md / diagnosis.json: what was wrong, where, what was missing, how much better it fits."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from geoback.outputs import write_atomic, write_json
from geoback.reports.resultsets import result_set
from geoback.reports.units import number, shown
from geoback.diagnosis.compare import detectable_text
from geoback.diagnosis.hypotheses import CAUSES
from geoback.diagnosis.procedure import NO_ADDITION


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
    """The hypothesis' parameters as refitted in its round (linearised intervals)."""
    rel, f = s.reliability, s.refit
    lo, hi = rel.interval95()
    out = []
    for name in s.hypothesis.names:
        i = rel.names.index(name)
        out.append((name, f.p[i], rel.std[i], lo[i], hi[i]))
    return out


def _num(v: float) -> str:
    return number(v, 4) if np.isfinite(v) else ("∞" if v > 0 else "-∞")


def _accepted_words(d, s) -> str:
    """One accepted hypothesis with its parameters from the final joint fit."""
    params = d.final.parameters
    case_unit = dict(zip(params.names, params.units))

    def one(n, v, sd, lo, hi):  # in engineering units: a modulus in MPa (units.shown)
        f, shown_unit = shown(case_unit.get(n, "-"), v)
        u = "" if shown_unit in ("-", "") else f" {shown_unit}"
        v, sd, lo, hi = v * f, sd * f, lo * f, hi * f
        lo_open, hi_open = d.open_ends(n)
        if lo_open or hi_open:
            ends = (f"from {'its lower limit' if lo_open else _num(lo)} to {'its upper limit' if hi_open else _num(hi)}"
                    f" by profile likelihood, open where the readings do not bound it")
            return f"{n} = {number(v, 4)}{u} (95 % {ends})"
        how = ", profile likelihood" if (n in d.final_intervals or n in d.final.profiled) else ""
        return f"{n} = {number(v, 4)} ± {number(sd, 2)}{u} (95 % [{_num(lo)}, {_num(hi)}]{how})"

    est = "; ".join(one(*e) for e in d.estimates(s))
    prof = d.depth_profile(s)
    title = s.hypothesis.title
    if prof is not None:
        title = f"a different stratum in '{prof.layer}' below {prof.z_hat:.3g} m (95 % {prof.interval_text()})"
    elif s.hypothesis.extra_values and s.hypothesis.kind != "layer-boundary":
        title += " at " + ", ".join(f"{k} = {v:g} m" for k, v in s.hypothesis.extra_values.items())
    text = f"{title}: {est}"
    if not s.determined:
        why = sorted({"it ended at a bound of its search" if c.code == "at-bound" else "its uncertainty is as large "
                      "as the value itself" for c in s.caveats})
        names = ", ".join(sorted({c.parameter for c in s.caveats if c.parameter} or set(s.hypothesis.names)))
        text += (f" - TENTATIVE: the readings do not determine {names} ({'; '.join(why)}); read it as where and "
                 f"which way, not how much")
    return text


def cause_words(d) -> str:
    """'instrument error', 'ground physics', both, or 'none'."""
    c = d.causes
    found = [CAUSES[k] for k in ("instrument", "ground") if c[k]]
    return " and ".join(found) if found else "none"


def rival_sentences(d) -> list[str]:
    """A plain statement for every round whose accepted hypothesis has a rival within 2 AIC."""
    out = []
    for rnd in d.rounds:
        if rnd.accepted is None or rnd.rival is None:
            continue
        a, b = rnd.accepted, rnd.rival
        wa, wb = rnd.weights.get(a.hypothesis.key, float("nan")), rnd.weights.get(b.hypothesis.key, float("nan"))
        sep = rnd.separation.text(a.hypothesis.title, b.hypothesis.title) if rnd.separation is not None else ""
        out.append(f"{_cap(a.hypothesis.title)} ({CAUSES[a.hypothesis.cause]}) and {b.hypothesis.title} "
                   f"({CAUSES[b.hypothesis.cause]}) fit about equally well (Akaike weights {wa:.2f} / {wb:.2f}, "
                   f"ΔAIC = {b.aic - a.aic:.2g}): the readings cannot tell them apart"
                   + (f"; {sep}" if sep else "") + ".")
    return out


def _cap(text: str) -> str:
    return text[:1].upper() + text[1:]


def detectable_sentence(d) -> str:
    rnd = d.rounds[-1]
    text = detectable_text(rnd.ranking, rnd.threshold)
    return (f"Its tests would have caught, with 80 % probability: {text}." if text else "")


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
        catch = detectable_sentence(d)
        return (f"The model is adequate: {_fit_line(b.chi2, b.dof, b.p_value)}{extra} - the readings are explained "
                f"within their stated errors{scaled}. No effect the library can detect is missing"
                + (f"; smaller effects may be. {catch}" if catch else "."))
    if not d.accepted:
        catch = detectable_sentence(d)
        return (f"The model does not explain the readings ({_fit_line(b.chi2, b.dof, b.p_value)}), but none of the "
                f"hypotheses in the library improves the fit significantly. Check the readings and their stated "
                f"errors, or the geometry." + (f" {catch}" if catch else ""))
    c = d.causes
    parts = []
    for cause in ("instrument", "ground"):
        if c[cause]:
            parts.append(f"{_cap(CAUSES[cause])}: " + " + ".join(_accepted_words(d, s) for s in c[cause]) + ".")
    if not c["ground"]:
        parts.append("Ground physics: no effect the library can detect beyond the instrument error.")
    f = d.final_reliability
    state = "adequate" if d.adequate_after else "still not adequate"
    lead = {"instrument": "The mismatch is instrument error, not ground physics.",
            "ground": "The mismatch is ground physics the model lacks.",
            "both": "The mismatch is instrument error and ground physics the model lacks."}[
        "both" if c["instrument"] and c["ground"] else ("instrument" if c["instrument"] else "ground")]
    numbers = " (numbers from the final joint fit)" if len(d.accepted) > 1 else ""
    return (f"{lead} Missing{numbers} - " + " ".join(parts) + " " + " ".join(rival_sentences(d))
            + f" Fit before: {_fit_line(b.chi2, b.dof, b.p_value)}; after: {_fit_line(f.chi2, f.dof, f.p_value)}"
              f" - {state}.").replace("  ", " ")


def diagnosis_text(d) -> str:
    lines = [f"# geoback diagnosis: {d.case}", "", verdict(d), ""]
    for k, rnd in enumerate(d.rounds, 1):
        lines += [f"## Round {k}", "", f"- fit: {_fit_line(rnd.chi2, rnd.dof, rnd.p_value)}"] + _scale_lines(rnd)
        if rnd.adequate and rnd.accepted is None:
            scales = (", every estimated error scale is within what the case allows"
                      if any(e.estimated for e in rnd.scales) else "")
            flagged = [s for s in rnd.ranking if s.collinear_with is None and s.p_score < rnd.threshold]
            tests = (f"no hypothesis' score test is significant at {rnd.threshold:.2g} (= {d.alpha:g} / number of "
                     f"hypotheses)" if not flagged else
                     f"the score test{'s' if len(flagged) > 1 else ''} of {', '.join(s.hypothesis.title for s in flagged)}"
                     f" {'are' if len(flagged) > 1 else 'is'} significant at {rnd.threshold:.2g}, but no refit "
                     f"improves the fit significantly (the score test is a linear approximation)")
            lines += [f"- adequate: the χ² test passes at the {100 * d.alpha:g} % level{scales} and {tests}; stop"]
        else:
            lines += ["- where the model and the readings differ:"] + [f"  - {m.text}" for m in rnd.mismatches[:4]]
        if rnd.ranking:
            lines += ["", "| hypothesis | cause | score S | p (score) | ΔJ | p (LR) | AIC | Akaike weight | BIC | "
                          "estimate (this round) |",
                      "|---|---|---|---|---|---|---|---|---|---|"]
            for s in rnd.ranking:
                cause = CAUSES[s.hypothesis.cause]
                if s.collinear_with:
                    lines.append(f"| {s.hypothesis.title} | {cause} | - | - | - | - | - | - | - | cannot be identified "
                                 f"together with {s.collinear_with}: same effect on the readings |")
                    continue
                est = ""
                if s.refit is not None:
                    est = "; ".join(f"{n} = {v:.4g} ± {sd:.2g}" for n, v, sd, _, _ in _estimates(s))
                    if s.profile is not None:
                        est += f" ({s.profile.text()})"
                    elif s.hypothesis.extra_values:
                        est += " (" + ", ".join(f"{k2} = {v:g}" for k2, v in s.hypothesis.extra_values.items()) + ")"
                    if not s.determined:
                        est += " **not determined**"
                fmt = (lambda v: f"{v:.4g}" if np.isfinite(v) else "-")
                lines.append(f"| {s.hypothesis.title} | {cause} | {fmt(s.score)} | {fmt(s.p_score)} | {fmt(s.dJ)} | "
                             f"{fmt(s.p_lr)} | {fmt(s.aic)} | {fmt(s.weight) if np.isfinite(s.weight) else '-'} | "
                             f"{fmt(s.bic)} | {est} |")
            if rnd.weights:
                lines += ["", f"Akaike weights over the refitted hypotheses and the model without them "
                              f"({NO_ADDITION}: {rnd.weights.get(NO_ADDITION, 0.0):.2g})."]
        if rnd.accepted is not None:
            tent = " (tentative: a parameter is not determined)" if rnd.tentative else ""
            lines += ["", f"Accepted{tent}: **{rnd.accepted.hypothesis.title}** ({CAUSES[rnd.accepted.hypothesis.cause]})"
                          f" - {rnd.accepted.hypothesis.description}"]
            if rnd.rival is not None:
                lines += ["", next((t for t in rival_sentences(_One(d, rnd))), "")]
        else:
            lines += ["", "No hypothesis is significant (likelihood-ratio test with Bonferroni correction)."]
            catch = detectable_text(rnd.ranking, rnd.threshold)
            if catch:
                lines += ["", f"No effect the library can detect is missing; its tests would have caught, with "
                              f"80 % probability: {catch}."]
        lines.append("")
    if d.accepted:
        lines += ["## Final joint fit", ""]
        lines += [f"- {CAUSES[s.hypothesis.cause]}: {_accepted_words(d, s)}" for s in d.accepted]
        for s in d.accepted:
            prof = d.depth_profile(s)
            if prof is not None:
                where = "re-profiled in the final model" if s.hypothesis.key in d.final_profiles else "profiled"
                lines.append(f"- boundary in '{prof.layer}' ({where}): {prof.text()}; J(z) at "
                             + ", ".join(f"{z:.3g} m: {J - prof.J_min:+.3g}" for z, J, _ in prof.points))
        lines.append("")
    return "\n".join(lines) + "\n"


class _One:
    """A view of a diagnosis with a single round (for that round's rival sentence)."""

    def __init__(self, d, rnd):
        self.rounds = [rnd]


def _item(d, s, final: bool) -> dict:
    item = {"key": s.hypothesis.key, "kind": s.hypothesis.kind, "cause": CAUSES[s.hypothesis.cause],
            "title": s.hypothesis.title, "description": s.hypothesis.description, "score": s.score,
            "score_dof": s.dof, "p_score": s.p_score, "collinear_with": s.collinear_with,
            "extra_values": s.hypothesis.extra_values,
            "detectable": s.detectable}
    if s.refit is not None:
        item.update(dJ=s.dJ, p_lr=s.p_lr, aic=s.aic, bic=s.bic, akaike_weight=s.weight, status=s.refit.status,
                    determined=s.determined, caveats=[c.as_dict() for c in s.caveats],
                    estimates={n: {"estimate": v, "std": sd, "ci95": [lo, hi]}
                               for n, v, sd, lo, hi in _estimates(s)})
        if s.profile is not None:
            item["depth"] = s.profile.as_dict()
    if final:  # an accepted hypothesis: its parameters from the final joint fit
        item["estimates_in_round"] = item.pop("estimates", {})
        item["estimates"] = {n: {"estimate": v, "std": sd, "ci95": [lo, hi], "from": "final joint fit",
                                 "interval": ("profile likelihood" if (n in d.final_intervals or n in d.final.profiled)
                                              else "linearised"), "ci95_open": list(d.open_ends(n))}
                             for n, v, sd, lo, hi in d.estimates(s)}
        prof = d.depth_profile(s)
        if prof is not None:
            item["depth"] = prof.as_dict()
            item["depth"]["from"] = ("final joint fit" if s.hypothesis.key in d.final_profiles
                                     else "profiled in its round (the last effect accepted)")
        item["tentative"] = not s.determined
    return item


def diagnosis_json(d) -> dict:
    b, f = d.baseline_reliability, d.final_reliability
    lo, hi = d.final.intervals95()
    c = d.causes
    return {
        "case": d.case, "alpha": d.alpha, "verdict": verdict(d),
        "adequate_before": d.adequate_before, "adequate_after": d.adequate_after,
        "cause": cause_words(d),
        "instrument_error": [s.hypothesis.key for s in c["instrument"]],
        "ground_physics": [s.hypothesis.key for s in c["ground"]],
        "rivals": rival_sentences(d),
        "detectable": detectable_text(d.rounds[-1].ranking, d.rounds[-1].threshold) if not d.accepted else "",
        "seconds": d.seconds,
        "before": {"chi2": b.chi2, "dof": b.dof, "reduced_chi2": b.reduced_chi2, "p_value": b.p_value,
                   "parameters": dict(zip(b.names, d.baseline_fit.p))},
        "after": {"chi2": f.chi2, "dof": f.dof, "reduced_chi2": f.reduced_chi2, "p_value": f.p_value,
                  "parameters": dict(zip(f.names, d.final_fit.p)), "std": dict(zip(f.names, f.std)),
                  "ci95": {n: [float(a), float(z)] for n, a, z in zip(f.names, lo, hi)},
                  "caveats": [cv.as_dict() for cv in d.final.caveats]},
        "missing": [_item(d, s, True) for s in d.accepted],
        "rounds": [{"chi2": r.chi2, "dof": r.dof, "p_value": r.p_value,
                    "error_scales": [e.as_dict() for e in r.scales if e.estimated],
                    "scale_threshold": r.scale_threshold, "threshold": r.threshold,
                    "mismatches": [m.__dict__ for m in r.mismatches],
                    "ranking": [_item(d, s, False) for s in r.ranking],
                    "akaike_weights": r.weights, "aic_without": r.aic,
                    "rival": r.rival.hypothesis.key if r.rival else None,
                    "separation": r.separation.as_dict() if r.separation is not None else None,
                    "accepted": r.accepted.hypothesis.key if r.accepted else None,
                    "tentative": r.tentative} for r in d.rounds],
    }


def write_diagnosis(d, out: Path, plots: bool = True, exploration=None) -> None:
    """diagnosis.md, diagnosis.json and (plots) diagnosis.png/.svg, replacing the previous set in `out`
    as a whole; `exploration` gives the figure the model along each instrument at the final fit."""
    with result_set(out, "diagnose") as staging:
        write_atomic(staging / "diagnosis.md", diagnosis_text(d))
        write_json(staging / "diagnosis.json", diagnosis_json(d))
        if plots:
            from geoback.reports.plots.diagnosis import plot_before_after

            plot_before_after(d, staging, exploration)
