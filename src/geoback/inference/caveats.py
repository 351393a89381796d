"""What a result should not be trusted for, said in words and as machine-readable codes.

Every caveat has a code (stable, for scripts and `--strict`), the parameter it concerns if any,
and a sentence that says what was found and what to check. Codes:

| code | when |
|---|---|
| `not-converged` | the iteration limit was reached |
| `did-not-move` | no step decreased J: the estimate is the initial value |
| `model-rejected` | χ² is too large for the stated measurement errors (p < 0.05) |
| `at-bound` | a parameter ended at one of its bounds (not at a natural limit: a prop without preload is a finding) |
| `not-determined` | the readings cannot fix a parameter or a combination (singular, or a 95 % interval wider than the parameter's usual range, or, for a quantity on a ratio scale (a modulus, not a preload whose 0 is a state it can be in), a coefficient of variation of 100 % or more) |
| `poorly-determined` | a coefficient of variation between 30 % and 100 % (a quantity on a ratio scale) |
| `implausible-value` | an estimate outside the usual range (for ground, or a concrete lining) |
| `implausible-input` | a value of the case outside the usual range (a unit slip?) |
| `exactly-determined` | as many readings as parameters: χ² cannot test the model |
| `mesh-error` | the mesh's discretisation error on a reading above 0.3 of its sigma |
| `error-scale` | an estimated error scale beyond what the case allows for it (its prior, or the other instruments) |
| `forecast-skipped` | the case's forecasts were not computed: the fit never moved from the initial values (``worth.forecast.unusable_estimate``) |
| `time-limit` | the fit was stopped at the time limit with its best point (``estimate.WARNINGS``) |
| `model-unsolved` | points the model could not be solved at were rejected steps, or the discretisation-error check was skipped |
| `forecast-nonlinear` | a forecast's linearised 95 % band and the range sampled through the model differ by more than 10 % |
| `instrument-misfit` | one instrument (or error-scale group) whose stated σ is taken as exact drives the misfit: its readings alone ask for a scale far above the others' (F test), with its share of J, the signs of its residuals and whether its readings run opposite to the computed ones |

Values are given in the unit the report's table uses for that parameter (its unit column).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geoback.case.limits import natural_limit

POORLY, UNDETERMINED = 0.30, 1.0  # coefficient of variation
ALPHA = 0.05


@dataclass(frozen=True)
class Caveat:
    code: str
    message: str
    parameter: str | None = None

    def as_dict(self) -> dict:
        return {"code": self.code, "parameter": self.parameter, "message": self.message}


def _value(v: float, unit: str) -> str:
    """A value in the parameter's own unit: the unit of the report's table (E in kPa there, so here)."""
    return f"{v:.4g}" + ("" if unit in ("-", "") else f" {unit}")


def fit_caveats(fit, rel, params, limits, profiled: dict) -> list[Caveat]:
    """Caveats of a fit and its reliability; limits[i] is parameter i's ``Limits`` (or None)."""
    out: list[Caveat] = []
    if fit.status != "converged" and fit.moved:
        out.append(Caveat("not-converged", f"the fit did not converge: {fit.reason}"))
    # what the fit itself warns of (estimate.WARNINGS: stopped at the time limit, points without a solution)
    # is a caveat here, where every result is concluded, so that the library's identify() says it as
    # `geoback run` does and nothing a fit knows about its end is left in a field no report reads
    out.extend(Caveat(code, message) for code, message in getattr(fit, "warnings", ()))
    if not fit.moved:
        out.append(Caveat("did-not-move", "the fit stopped without moving from the initial values: no step "
                                          "decreased J (check the initial values and bounds; try --method lm)"))
    if rel.total_dof == 0:  # (rel.dof is 0 too when every instrument's scale is estimated: not this)
        out.append(Caveat("exactly-determined", "as many readings as parameters: the fit is exact and chi-square "
                                                "cannot test the model"))
    elif rel.dof > 0 and rel.p_value < ALPHA:
        out.append(Caveat("model-rejected",
                          f"the model does not explain the readings within their stated errors: chi-square/dof = "
                          f"{rel.reduced_chi2:.3g} (p = {rel.p_value:.2g}); check the readings (order, signs, units, "
                          f"reference end) and their stated sigma, then run `geoback diagnose`"))
    for e in getattr(rel, "error_scales", ()):
        if e.estimated and e.p_allowed < ALPHA:
            out.append(Caveat("error-scale", e.text + "; try `geoback diagnose`", e.name))
    for combo in rel.undetermined:
        out.append(Caveat("not-determined", f"the readings cannot determine {combo} (standard deviations of the "
                                            f"parameters involved are infinite)"))
    for i, name in enumerate(params.names):
        unit = params.units[i]
        p, sd = float(fit.p[i]), float(rel.std[i])
        lim = limits[i]
        if fit.at_bound[i] and not natural_limit(lim, p):  # (a fit at a natural limit, no preload, is a finding)
            lo, hi = params.lower[i], params.upper[i]
            which = lo if abs(p - lo) <= abs(p - hi) else hi
            out.append(Caveat("at-bound", f"{name} ended at its bound {_value(which, unit)}: the readings push it "
                                          f"further (or the bound is wrong); its interval is not meaningful", name))
        if np.isfinite(sd) and lim is not None:
            positive = lim.ratio_scale
            cv = sd / abs(p) if p != 0 else np.inf
            wide = 2 * 1.96 * sd > (lim.plausible[1] - lim.plausible[0])
            if (positive and cv >= UNDETERMINED) or (not positive and wide):
                interval = ""
                if name in profiled:
                    lo, hi, lo_open, hi_open = profiled[name]
                    interval = (f"; 95 % profile-likelihood interval from "
                                f"{'its lower limit' if lo_open else _value(lo, unit)} to "
                                f"{'its upper limit' if hi_open else _value(hi, unit)}")
                out.append(Caveat("not-determined",
                                  f"{name} is not determined by the readings ({p:.4g} ± "
                                  f"{_value(sd, unit)}{f', {100 * cv:.0f} %' if positive else ''}{interval}): no "
                                  f"instrument sees it enough; fix it at a value or give it a prior", name))
            elif positive and cv >= POORLY:
                out.append(Caveat("poorly-determined", f"{name} is poorly determined ({100 * cv:.0f} % coefficient "
                                                       f"of variation)", name))
        if lim is not None and not (lim.plausible[0] <= p <= lim.plausible[1]):
            out.append(Caveat("implausible-value", f"{name} = {_value(p, unit)} is outside the usual range for "
                                                   f"{getattr(lim, 'usual_for', 'ground')} ({_value(lim.plausible[0], unit)} to "
                                                   f"{_value(lim.plausible[1], unit)})", name))
    return out


def status_words(fit, rel) -> str:
    """The one-line status that tells the truth."""
    if not fit.moved:
        return "stopped without moving"
    if fit.status != "converged":
        return "not converged"
    if rel.dof > 0 and rel.p_value < ALPHA:
        return f"converged; model inadequate (p = {rel.p_value:.2g})"
    return "converged"


def instrument_caveats(rel, data, computed, whiten=None, alpha: float = ALPHA) -> list[Caveat]:
    """The instrument that drives the misfit, named (code `instrument-misfit`): among the error-scale
    groups whose σ is taken as stated (each instrument is its own group unless the case groups
    them), the one with the largest share of J at the stated σ's, when its readings are not
    consistent with its stated σ (``ScaleEstimate.p_stated``) and ask for a scale above the pooled
    scale of all the others by the F test of ``scale_estimates.others_p``
    (Bonferroni over the groups) and by a factor 2 or more. Said with its share of J, its own error
    scale (sqrt(J_g / c_g), c_g its readings less the parameters' share), the signs of its
    residuals (a sign test) and the factor a that best matches its readings by the computed
    values, x* ~ a x (whitened by its stated C_x with `whiten(block, values, covariance)`, the
    seam's ``misfit.whiten_block``): a < 0, readings running opposite to the model, points to a
    sign convention, a reference end or a swapped component. Costs no model run."""
    from geoback.inference.scale_estimates import others_p

    groups = [e for e in getattr(rel, "error_scales", ()) if np.isfinite(e.J) and e.dof > 0]
    if len(groups) < 2 or data.measured is None:
        return []
    J_all = sum(e.J for e in groups)
    c_all = sum(e.dof for e in groups)
    top = max(groups, key=lambda e: e.J)
    if top.estimated or J_all <= 0:  # an estimated scale has its own test (code error-scale)
        return []
    if not (top.readings_factor > 1 and np.isfinite(top.p_stated) and top.p_stated < alpha):
        return []  # its readings are consistent with its stated sigma: nothing drives a misfit
    ratio, p = others_p(top.J, top.dof, J_all - top.J, c_all - top.dof)
    if not (np.isfinite(p) and p < alpha / len(groups) and ratio >= 2.0):
        return []
    rows = np.array([i for i, lab in enumerate(data.labels) if lab.instrument in top.instruments], np.int64)
    measured, x = data.measured[rows], np.asarray(computed, float)[rows]
    r = measured - x
    who = top.name if len(top.instruments) == 1 else f"{top.name} ({', '.join(top.instruments)})"
    text = (f"{who} drives the misfit: {100 * top.J / J_all:.0f} % of J from {len(rows)} of {data.m} readings; "
            f"its readings alone ask for {top.readings_factor:.2g}× its stated σ ({100 * top.level:g} % "
            f"[{top.low:.2g}, {top.high:.2g}]), {ratio:.2g}× the other instruments' (F test p = {p:.2g})")
    negative, positive = int(np.sum(r < 0)), int(np.sum(r > 0))
    if len(rows) >= 3 and min(negative, positive) == 0:
        n = negative + positive
        text += (f"; all {n} of its residuals (measured - computed) are {'negative' if negative else 'positive'} "
                 f"(sign test p = {min(1.0, 2 * 0.5 ** n):.2g})")
    a = float("nan")
    if whiten is not None:
        try:
            xw, mw = [], []
            for block, sl in data.block_rows():
                if block.name in top.instruments:
                    xw.append(whiten(block, np.asarray(computed, float)[sl], data.covariance[sl, sl]))
                    mw.append(whiten(block, data.measured[sl], data.covariance[sl, sl]))
            xw, mw = np.concatenate(xw), np.concatenate(mw)
            a = float(xw @ mw / (xw @ xw)) if xw @ xw > 0 else float("nan")
        except (np.linalg.LinAlgError, ValueError):
            a = float("nan")
    if np.isfinite(a) and a < 0:
        text += (f"; its readings run opposite to the computed ones (best match x* = {a:.2g} × computed): check "
                 f"its sign convention, its reference end and its units")
    else:
        text += "; check its readings (order, units, reference end) and its stated σ"
    return [Caveat("instrument-misfit", text, None)]
