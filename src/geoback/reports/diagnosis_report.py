"""diagnosis.md / diagnosis.json / amended.yaml: what was wrong, where, what was missing, how much
better it fits, every parameter before and after, and the case amended to go on with."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from geoback.outputs import write_atomic, write_json
from geoback.reports.resultsets import result_set
from geoback.diagnosis.claims import RIVAL_AIC, overdispersion
from geoback.diagnosis.compare import EQUAL_AIC, detectable_text, unit_of
from geoback.diagnosis.hypotheses import CAUSES, KINDS
from geoback.diagnosis.procedure import NO_ADDITION
from geoback.diagnosis.results import GRADES
from geoback.units import display, interval_text, pm_text, value_text
from geoback.diagnosis.amend import AMENDED, amended_text
from geoback.diagnosis.yielding import adopted_title


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
    """The hypothesis' parameters as refitted in its round (linearised intervals, as `run` gives
    them: none (nan) where the refit did not converge, in ln p where a positive quantity's would
    cross its lower limit)."""
    from geoback.inference.identification import interval_records
    from geoback.inference.parameters import parameter_limits

    rel, f, params = s.reliability, s.refit, s.misfit.parameters
    values = s.misfit.values(f.p)
    limits = [parameter_limits(s.misfit.simulation, n, values) for n in params.names]
    records = interval_records(f, rel, params, limits, {})
    out = []
    for name in s.hypothesis.names:
        i = rel.names.index(name)
        lo, hi = (float("nan"), float("nan")) if name in s.at_bound else (records[i].low, records[i].high)
        out.append((name, f.p[i], rel.std[i], lo, hi))
    return out


BOUND_WORDS = "at its search bound; not determined"


def _check_words(s) -> str:
    """The claim checks an accepted cause failed, in words."""
    return "; ".join(c.text for c in s.checks.values() if not c.passed and c.name != "rivals")  # rivals: own words


def _rival_words(s) -> str:
    """The rivals of other families of an accepted cause, each with what would tell it from the cause."""
    if not s.rivals:
        return ""

    def one(r) -> str:
        sep = s.separations.get(r.hypothesis.key)
        told = sep.text(s.hypothesis.title, r.hypothesis.title) if sep is not None else ""
        return (f"{r.hypothesis.title} ({CAUSES[r.hypothesis.cause]}, ΔAIC {r.aic - s.aic:+.2g}"
                + (f"; what would tell them apart: {told}" if told else "") + ")")

    return ("it is not singled out from " + " or from ".join(one(r) for r in s.rivals)
            + "; `geoback design --separate` ranks candidate instruments for it")


def _unit(params, name: str) -> str:
    return params.units[params.names.index(name)] if name in params.names else "-"


def _accepted_words(d, s) -> str:
    """One accepted hypothesis with its parameters from the final joint fit, in engineering units."""
    params = d.final.parameters

    def one(n, v, sd, lo, hi):
        unit = _unit(params, n)
        if d.bound_of(n) or n in s.at_bound:
            return f"{n} = {value_text(n, unit, v)} ({BOUND_WORDS})"
        if s.grade == "explained":  # not found: no interval as if it were
            return f"{n} = {value_text(n, unit, v)} if it were the cause (no interval: not singled out)"
        lo_open, hi_open = d.open_ends(n)
        if not (np.isfinite(lo) and np.isfinite(hi)):
            reason = d.final.interval(n).reason if n in params.names else ""
            return f"{n} = {pm_text(n, unit, v, sd)} (no 95 % interval: {reason or 'not determined'})"
        if lo_open or hi_open:
            ends = (f"from {'its lower limit' if lo_open else value_text(n, unit, lo)} to "
                    f"{'its upper limit' if hi_open else value_text(n, unit, hi)}, open where the readings do not bound it")
            return f"{n} = {value_text(n, unit, v)} (95 % {ends})"
        how = ", profile likelihood" if (n in d.final_intervals or n in d.final.profiled) else ""
        if strength is not None and n == f"c[{strength.layer}]":
            how = ", profile likelihood with phi' and psi not assumed"
        sel = selective.get(n)
        near = ""
        if sel is not None and sel.noticeable:  # near the detection limit: the interval allowing for it too
            near = (f"; {interval_text(n, unit, sel.low, sel.high)} allowing for its selection near the detection "
                    f"limit (accepted as |z| = {abs(sel.z):.2f} exceeded {sel.c:.2f})")
        return f"{n} = {pm_text(n, unit, v, sd)} (95 % {interval_text(n, unit, lo, hi)}{how}{near})"

    selective = d.selective(s)
    strength = d.strength.get(s.hypothesis.key)  # a yielding layer's strength with phi' and psi profiled out
    est = "; ".join(one(*e) for e in d.estimates(s))
    prof = d.depth_profile(s)
    title = adopted_title(s.hypothesis.title, strength)
    if prof is not None and s.grade == "explained":
        title = f"a different stratum in '{prof.layer}' below about {prof.z_hat:.3g} m"
    elif prof is not None:
        title = f"a different stratum in '{prof.layer}' below {prof.z_hat:.3g} m (95 % {prof.interval_text()})"
    elif s.hypothesis.extra_values and s.hypothesis.kind not in ("layer-boundary", "supported-release"):
        title += " at " + ", ".join(f"{k} = {v:g} m" for k, v in s.hypothesis.extra_values.items())
    text = f"{title}: {est}"
    same = d.interface(s)
    if same is not None:
        text += f" - {interface_sentence(same)}"
    if s.grade == "explained":
        why = "; ".join(w for w in (_check_words(s), _rival_words(s)) if w)
        text = f"{title} - EXPLAINED BUT NOT SINGLED OUT ({why}): {est}"
    if strength is not None and s.grade != "explained":
        text += f"; {strength.words()}"
    elif strength is not None and strength.angles_words():  # not singled out: no interval, what the angles say
        text += f"; {strength.angles_words()}"
    if not s.determined:
        why = sorted({"it ended at a bound of its search" if c.code == "at-bound" else "its uncertainty is as large "
                      "as the value itself" for c in s.caveats})
        names = ", ".join(sorted({c.parameter for c in s.caveats if c.parameter} or set(s.hypothesis.names)))
        text += (f" - TENTATIVE: the readings do not determine {names} ({'; '.join(why)}); read it as where and "
                 f"which way, not how much")
    return text


def interface_sentence(same: dict) -> str:
    """``Diagnosis.interface`` in words: the case's interface at another depth."""
    mpa = lambda v: f"{v / 1000:.3g}"  # noqa: E731 - kPa as MPa
    where = "above" if same["part"] == "upper" else "below"
    moved = (f"'{same['neighbour']}' may reach {same['z']:.3g} m rather than the {same['stated']:.3g} m the case states"
             if same["part"] == "upper" else
             f"'{same['neighbour']}' may begin at {same['z']:.3g} m rather than the {same['stated']:.3g} m the case "
             f"states")
    return (f"the ground of '{same['layer']}' {where} {same['z']:.3g} m is as stiff as '{same['neighbour']}' "
            f"({mpa(same['E'])} against {mpa(same['E_neighbour'])} MPa, the difference within its 95 % interval of "
            f"± {mpa(same['half_width'])} MPa): {moved}")


def cause_words(d) -> str:
    """'instrument error', 'ground physics', both, or 'none'."""
    c = d.causes
    found = [CAUSES[k] for k in ("instrument", "ground") if c[k]]
    return " and ".join(found) if found else "none"


def rival_sentences(d) -> list[str]:
    """A plain statement for every rival of a round's accepted hypothesis (a refit within EQUAL_AIC, or of
    another family within the evidence of check 3), in words graded by the AIC difference (divided by the
    overdispersion check 3 allows for): within EQUAL_AIC the two fit about equally well; beyond it one fits
    better, but not by the RIVAL_AIC units that single a cause out."""
    out = []
    for rnd in d.rounds:
        a = rnd.accepted
        if a is None:
            continue
        pairs = [(b, a.separations.get(b.hypothesis.key)) for b in a.rivals]
        if rnd.rival is not None and rnd.rival not in a.rivals:
            pairs.insert(0, (rnd.rival, rnd.separation))
        c = overdispersion(a)
        for b, sep in pairs:
            first, second = (a, b) if b.aic >= a.aic else (b, a)
            delta = second.aic - first.aic
            numbers = (f"Akaike weights {rnd.weights.get(first.hypothesis.key, float('nan')):.2g} / "
                       f"{rnd.weights.get(second.hypothesis.key, float('nan')):.2g}, ΔAIC = {delta:.2g}"
                       + (f", {delta / c:.2g} divided by the χ²/dof {c:.3g} the refit leaves" if c > 1 else ""))
            if delta / c < EQUAL_AIC:
                text = (f"{_cap(_named(first))} and {_named(second)} fit about equally well ({numbers}): the "
                        f"readings cannot tell them apart")
            else:
                text = (f"{_cap(_named(first))} fits better than {_named(second)} ({numbers}), but not by the "
                        f"{RIVAL_AIC:.3g} AIC units that single a cause out: {second.hypothesis.title} keeps some "
                        f"support, and the readings do not tell them apart with confidence")
            told = sep.text(a.hypothesis.title, b.hypothesis.title) if sep is not None else ""
            out.append(text + (f"; {told}" if told else "") + ".")
    return out


def _named(s) -> str:
    return f"{s.hypothesis.title} ({CAUSES[s.hypothesis.cause]})"


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
                f"hypotheses in the library improves the fit significantly: no effect the library can detect. Check the "
                f"readings and their stated "
                f"errors, or the geometry." + (f" {catch}" if catch else ""))
    c = d.causes
    if d.grade == "explained":
        return _explained_verdict(d)
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


def _explained_verdict(d) -> str:
    """The verdict when an accepted cause failed a claim check: what improves the fit, why it is not
    singled out, and what it would take."""
    b, f = d.baseline_reliability, d.final_reliability
    named = [s for s in d.accepted if s.grade == "named"]
    lead = ("The readings are explained but the cause is not singled out: the library's best explanation "
            "improves the fit but does not pass every check a true cause passes.")
    if len(d.accepted) > 1:
        lead += " Numbers from the final joint fit:"
    parts = [f"{_cap(CAUSES[s.hypothesis.cause])}: " + _accepted_words(d, s) + "." for s in d.accepted]
    tail = (" Named: " + ", ".join(s.hypothesis.title for s in named) + "." if named else
            " No cause is named; read the fit's improvement as where the model and the readings differ, not as "
            "what the ground is.")
    state = "adequate" if d.adequate_after else "still not adequate"
    return (f"{lead} " + " ".join(parts) + tail
            + f" Fit before: {_fit_line(b.chi2, b.dof, b.p_value)}; after: {_fit_line(f.chi2, f.dof, f.p_value)}"
              f" - {state}.").replace("  ", " ")


def diagnosis_text(d) -> str:
    lines = [f"# geoback diagnosis: {d.case}", "", verdict(d), ""]
    for kind, why in getattr(d, "not_applicable", []):
        lines += [f"Not tested: {kind} ({KINDS.get(kind, kind)}): {why}.", ""]
    for k, rnd in enumerate(d.rounds, 1):
        lines += [f"## Round {k}", "", f"- fit: {_fit_line(rnd.chi2, rnd.dof, rnd.p_value)}"] + _scale_lines(rnd)
        if rnd.adequate and rnd.accepted is None:
            scales = (", every estimated error scale is within what the case allows"
                      if any(e.estimated for e in rnd.scales) else "")
            flagged = [s for s in rnd.ranking if s.collinear_with is None and s.p_score < rnd.threshold]
            tests = (f"no hypothesis' score test is significant at {rnd.threshold:.2g} (= "
                     f"{rnd.family_words(d.alpha)})" if not flagged else
                     f"the score test{'s' if len(flagged) > 1 else ''} of {', '.join(s.hypothesis.title for s in flagged)}"
                     f" {'are' if len(flagged) > 1 else 'is'} significant at {rnd.threshold:.2g}, but no refit "
                     f"improves the fit significantly (the score test is a linear approximation)")
            lines += [f"- adequate: the χ² test passes at the {100 * d.alpha:g} % level{scales} and {tests}; stop"]
        else:
            lines += ["- where the model and the readings differ:"] + [f"  - {m.text}" for m in rnd.mismatches[:4]]
        if rnd.ranking:
            lines += ["", f"{rnd.hypotheses} hypotheses scored, one row per test (a layer boundary's depths are one "
                          f"test: its row is the depth scoring highest, its p Bonferroni over the depths); level "
                          f"{rnd.threshold:.2g} per test (= {rnd.family_words(d.alpha)}).",
                      "", "| hypothesis | cause | score S | p (score) | ΔJ | p (LR) | AIC | Akaike weight | BIC | "
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
                    est = "; ".join(f"{n} = {pm_text(n, unit_of(s, n), v, sd)}" for n, v, sd, _, _ in _estimates(s))
                    if s.profile is not None:
                        est += f" ({s.profile.text()})"
                    elif s.hypothesis.extra_values:
                        est += " (" + ", ".join(f"{k2} = {v:g} m" for k2, v in s.hypothesis.extra_values.items()) + ")"
                    if s.at_bound:
                        est += f" **{BOUND_WORDS}**"
                    elif not s.determined:
                        est += " **not determined**"
                    if s.worse:
                        est += " **worse than the model it extends: no improvement**"
                fmt = (lambda v: f"{v:.4g}" if np.isfinite(v) else "-")
                p_cell = fmt(s.p_score)
                if s.group_size > 1 and np.isfinite(s.p_single):
                    p_cell += f" ({s.p_single:.2g} at this depth × {s.group_size} depths, Bonferroni)"
                lines.append(f"| {s.hypothesis.title} | {cause} | {fmt(s.score)} | {p_cell} | {fmt(s.dJ)} | "
                             f"{fmt(s.p_lr)} | {fmt(s.aic)} | {fmt(s.weight) if np.isfinite(s.weight) else '-'} | "
                             f"{fmt(s.bic)} | {est} |")
            if rnd.weights:
                lines += ["", f"Akaike weights over the refitted hypotheses and the model without them "
                              f"({NO_ADDITION}: {rnd.weights.get(NO_ADDITION, 0.0):.2g})."]
        if rnd.accepted is not None:
            tent = " (tentative: a parameter is not determined)" if rnd.tentative else ""
            acc = rnd.accepted
            lines += ["", f"Accepted{tent}: **{acc.hypothesis.title}** ({CAUSES[acc.hypothesis.cause]})"
                          f" - {acc.hypothesis.description}"]
            if acc.checks:
                lines += ["", f"Claim checks ({GRADES[acc.grade] if acc.grade else 'not graded'}):"]
                lines += [f"- {c.name}: {'passes' if c.passed else 'FAILS'} - {c.text}" for c in acc.checks.values()]
            for sentence in rival_sentences(_One(d, rnd)):
                lines += ["", sentence]
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
        lines += [""] + before_after_lines(d) + [""]
        lines += [f"The amended case `{AMENDED}` (in this folder) has the accepted extensions in its model and starts "
                  f"from these estimates: `geoback run {AMENDED}` reproduces the final joint fit, and forecasts and "
                  f"`geoback design` go on from it.", ""]
    return "\n".join(lines) + "\n"


def before_after(d) -> list[dict]:
    """Every parameter of the final joint fit, before (the case's model fitted; None for a parameter
    an accepted extension added, with its null value: where that extension is switched off) and
    after (the final joint fit): estimate, std, 95 % interval (None with the reason where there is
    none), in SI units (the unit given) and as shown."""
    before, after = d.baseline, d.final
    nulls = {q.name: q.initial for s in d.accepted for q in s.hypothesis.parameters}

    def side(res, name):
        if name not in res.parameters.names:
            return None
        e = res[name]
        return {"estimate": e.value, "std": e.std, "ci95": None if e.interval is None else [e.low, e.high],
                "ci95_method": e.method, "ci95_open": list(e.open), **({"ci95_reason": e.reason} if e.reason else {})}

    accepted = {}  # an accepted parameter as the verdict gives it (profiles, a boundary's depth profiled out)
    for s in d.accepted:
        for n, v, sd, lo, hi in d.estimates(s):
            prof = d.depth_profile(s) is not None
            how = ("profile likelihood" + (", the depth profiled out" if prof else "")
                   if (n in d.final_intervals or n in d.final.profiled or prof) else after.interval(n).method)
            accepted[n] = {"estimate": v, "std": sd, "ci95": [lo, hi] if np.isfinite(lo) and np.isfinite(hi) else None,
                           "ci95_method": how if np.isfinite(lo) and np.isfinite(hi) else "none",
                           "ci95_open": list(d.open_ends(n)),
                           **({"ci95_reason": after.interval(n).reason} if after.interval(n).reason else {})}
    out = []
    for i, name in enumerate(after.parameters.names):
        unit = after.parameters.units[i]
        out.append({"name": name, "unit": unit, "shown_in": display(name, unit)[0], "before": side(before, name),
                    "added": name not in before.parameters.names, "null_value": nulls.get(name),
                    "after": accepted.get(name) or side(after, name)})
    return out


def before_after_lines(d) -> list[str]:
    """The before/after table of diagnosis.md: every parameter, its estimate ± std and 95 % interval
    before the diagnosis (the case's model) and in the final joint fit, in engineering units."""
    def cell(name, unit, side):
        if side is None:
            return "-"
        text = pm_text(name, unit, side["estimate"], side["std"])
        if side["ci95"] is None:
            return f"{text}; no 95 % interval: {side.get('ci95_reason', '')}"
        how = "" if side["ci95_method"] == "linearised" else f" ({side['ci95_method']})"
        lo_open, hi_open = side["ci95_open"]
        lo = "its lower limit" if lo_open else value_text(name, unit, side["ci95"][0]).split(" ")[0]
        hi = "its upper limit" if hi_open else value_text(name, unit, side["ci95"][1]).split(" ")[0]
        return f"{text}; 95 % [{lo}, {hi}]{how}"

    lines = ["Every parameter before (the case's model fitted) and after (the final joint fit), 95 % intervals:", "",
             "| parameter | unit | before | after |", "|---|---|---|---|"]
    for row in before_after(d):
        name, unit = row["name"], row["unit"]
        before = cell(name, unit, row["before"])
        if row["before"] is None:
            null = row["null_value"]
            before = ("not in the model" + (f" (the model without it: {value_text(name, unit, null)})"
                                            if null is not None else ""))
        lines.append(f"| {name} | {row['shown_in'] if row['shown_in'] not in ('-', '') else '-'} | {before} | "
                     f"{cell(name, unit, row['after'])} |")
    return lines


class _One:
    """A view of a diagnosis with a single round (for that round's rival sentences)."""

    def __init__(self, d, rnd):
        self.rounds = [rnd]


def _item(d, s, final: bool) -> dict:
    item = {"key": s.hypothesis.key, "kind": s.hypothesis.kind, "cause": CAUSES[s.hypothesis.cause],
            "title": s.hypothesis.title, "description": s.hypothesis.description, "score": s.score,
            "score_dof": s.dof, "p_score": s.p_score, "group_size": s.group_size,
            "p_score_single": s.p_single if s.group_size > 1 else s.p_score, "collinear_with": s.collinear_with,
            "extra_values": s.hypothesis.extra_values,
            "detectable": s.detectable}
    if s.refit is not None:
        status = s.refit.status if not s.worse else "worse than the model it extends"
        item.update(dJ=s.dJ, p_lr=s.p_lr, aic=s.aic, bic=s.bic, akaike_weight=s.weight, status=status,
                    improves=not s.worse, determined=s.determined and not s.at_bound,
                    caveats=[c.as_dict() for c in s.caveats],
                    estimates={n: {"estimate": v, "std": sd, "unit": unit_of(s, n),
                                   "ci95": [lo, hi] if np.isfinite(lo) and np.isfinite(hi) else None,
                                   **({"at_bound": s.at_bound[n], "note": BOUND_WORDS} if n in s.at_bound else {})}
                               for n, v, sd, lo, hi in _estimates(s)})
        if s.profile is not None:
            item["depth"] = s.profile.as_dict()
    if final:  # an accepted hypothesis: its parameters from the final joint fit
        item["estimates_in_round"] = item.pop("estimates", {})

        def entry(n, v, sd, lo, hi):
            bound = d.bound_of(n) or s.at_bound.get(n)
            shown = np.isfinite(lo) and np.isfinite(hi) and not bound and s.grade != "explained"
            e = {"estimate": v, "std": sd, "unit": _unit(d.final.parameters, n), "ci95": [lo, hi] if shown else None,
                 "from": "final joint fit",
                 "interval": ("profile likelihood" if (n in d.final_intervals or n in d.final.profiled)
                              else "linearised"), "ci95_open": list(d.open_ends(n))}
            if bound:
                e.update(at_bound=bound, note=BOUND_WORDS)
            elif s.grade == "explained":
                e["note"] = "explained but not singled out: no interval as if it were found"
            if shown:  # the interval allowing for the cause's selection at its round's level (selection.py)
                sel = selective.get(n)
                e["ci95_selective"] = sel.as_dict() if sel is not None else None
            return e

        selective = d.selective(s)

        item["estimates"] = {e[0]: entry(*e) for e in d.estimates(s)}
        item["grade"] = GRADES.get(s.grade, s.grade)
        item["checks"] = {k: c.as_dict() for k, c in s.checks.items()}
        item["rivals"] = [{"key": r.hypothesis.key, "kind": r.hypothesis.kind, "title": r.hypothesis.title,
                           "cause": CAUSES[r.hypothesis.cause], "dAIC": r.aic - s.aic,
                           "separation": (s.separations[r.hypothesis.key].as_dict()
                                          if r.hypothesis.key in s.separations else None)} for r in s.rivals]
        prof = d.depth_profile(s)
        if prof is not None:
            item["depth"] = prof.as_dict()
            item["depth"]["from"] = ("final joint fit" if s.hypothesis.key in d.final_profiles
                                     else "profiled in its round (the last effect accepted)")
            same = d.interface(s)  # one part of the split layer as stiff as the layer next to it, or null
            item["interface"] = None if same is None else {**same, "words": interface_sentence(same)}
        if s.hypothesis.key in d.strength:
            item["strength"] = d.strength[s.hypothesis.key].as_dict()
        item["tentative"] = not s.determined
    return item


def diagnosis_json(d) -> dict:
    b, f = d.baseline_reliability, d.final_reliability
    lo, hi = d.final.intervals95()
    c = d.causes
    return {
        "case": d.case, "alpha": d.alpha, "verdict": verdict(d), "grade": GRADES[d.grade],
        "adequate_before": d.adequate_before, "adequate_after": d.adequate_after,
        "cause": cause_words(d),
        "instrument_error": [s.hypothesis.key for s in c["instrument"]],
        "ground_physics": [s.hypothesis.key for s in c["ground"]],
        "rivals": rival_sentences(d),
        "not_tested": [{"kind": k, "why": why} for k, why in getattr(d, "not_applicable", [])],
        "detectable": detectable_text(d.rounds[-1].ranking, d.rounds[-1].threshold) if not d.accepted else "",
        "seconds": d.seconds,
        "before": {"chi2": b.chi2, "dof": b.dof, "reduced_chi2": b.reduced_chi2, "p_value": b.p_value,
                   "parameters": dict(zip(b.names, d.baseline_fit.p))},
        "after": {"chi2": f.chi2, "dof": f.dof, "reduced_chi2": f.reduced_chi2, "p_value": f.p_value,
                  "parameters": dict(zip(f.names, d.final_fit.p)), "std": dict(zip(f.names, f.std)),
                  "ci95": {n: ([float(a), float(z)] if np.isfinite(a) and np.isfinite(z) else None)
                           for n, a, z in zip(f.names, lo, hi)},
                  "units": dict(zip(f.names, d.final.parameters.units)),
                  "status": d.final.status, "caveats": [cv.as_dict() for cv in d.final.caveats]},
        "parameters": before_after(d),
        "amended_case": AMENDED if d.accepted else None,
        "missing": [_item(d, s, True) for s in d.accepted],
        "rounds": [{"chi2": r.chi2, "dof": r.dof, "p_value": r.p_value,
                    "error_scales": [e.as_dict() for e in r.scales if e.estimated],
                    "scale_threshold": r.scale_threshold, "threshold": r.threshold,
                    "hypotheses_scored": r.hypotheses, "tests": r.tests, "screened": r.screened,
                    "bonferroni_family": r.family,
                    "mismatches": [m.__dict__ for m in r.mismatches],
                    "ranking": [_item(d, s, False) for s in r.ranking],
                    "akaike_weights": r.weights, "aic_without": r.aic,
                    "rival": r.rival.hypothesis.key if r.rival else None,
                    "separation": r.separation.as_dict() if r.separation is not None else None,
                    "accepted": r.accepted.hypothesis.key if r.accepted else None,
                    "tentative": r.tentative} for r in d.rounds],
    }


def final_plastic_zone(d):
    """Where the ground yields in the final joint fit, when a yielding cause was accepted (a
    ``plastic_zone.PlasticZone``, at the final estimate and with the angles the model took), else None."""
    if not any(s.hypothesis.kind == "yielding" for s in d.accepted):
        return None
    return d.final_misfit.simulation.plastic_zone(d.final_misfit.values(d.final_fit.p))


def write_diagnosis(d, out: Path, plots: bool = True, exploration=None) -> None:
    """diagnosis.md, diagnosis.json and (plots) diagnosis.png/.svg, replacing the previous set in `out`
    as a whole; `exploration` gives the figure the model along each instrument at the final fit. Where
    yielding was accepted, also the plastic zone of the final joint fit: its section in diagnosis.md,
    plastic_zone.csv, "plastic_zone" in diagnosis.json and (plots) plastic_zone.png/.svg."""
    from geoback.reports.html import DIAGNOSIS_HOW_TO_READ, write_html

    zone = final_plastic_zone(d)
    with result_set(out, "diagnose") as staging:
        text = diagnosis_text(d)
        js = diagnosis_json(d)
        if zone is not None:
            from geoback.reports.fields import write_plastic_zone

            write_plastic_zone(zone, staging)
            js["plastic_zone"] = zone.as_dict()
            text += "\n".join(zone.lines("Plastic zone of the final joint fit")) + "\n"
        write_json(staging / "diagnosis.json", js)
        if d.accepted and d.loaded is not None:  # paths in it relative to `out`, where it ends up
            write_atomic(staging / AMENDED, amended_text(d, Path(out)))
        if plots:
            from geoback.reports.plots.diagnosis import plot_before_after

            plot_before_after(d, staging, exploration)
            what = "Measured and computed readings along every instrument, before and after the diagnosis"
            text += f"\n## Figures\n\n**Figure 1.** {what} (diagnosis.png; vector graphics: diagnosis.svg).\n\n" \
                    f"![Figure 1: {what}](diagnosis.png)\n"
            if zone is not None:
                from geoback.reports.plots import save_figures
                from geoback.reports.plots.plastic import plastic_zone_figure

                fig = plastic_zone_figure(zone, d.final, at="in the final joint fit of the diagnosis")
                try:
                    save_figures({"plastic_zone": fig}, staging)
                finally:
                    fig.clear()
                what = "Where the ground yields in the final joint fit, after every stage"
                text += f"\n**Figure 2.** {what} (plastic_zone.png; vector graphics: plastic_zone.svg).\n\n" \
                        f"![Figure 2: {what}](plastic_zone.png)\n"
        write_atomic(staging / "diagnosis.md", text)
        write_html(staging / "diagnosis.html", text, staging, name=d.case, kind="diagnosis report",
                   how_to_read=DIAGNOSIS_HOW_TO_READ)
