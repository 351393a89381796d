"""What a result should not be trusted for, said in words and as machine-readable codes.

Every caveat has a code (stable, for scripts and `--strict`), the parameter it concerns if any,
and a sentence that says what was found and what to check. Codes:

| code | when |
|---|---|
| `not-converged` | the iteration limit was reached |
| `did-not-move` | no step decreased J: the estimate is the initial value |
| `model-rejected` | χ² is too large for the stated measurement errors (p < 0.05) |
| `at-bound` | a parameter ended at one of its bounds |
| `not-determined` | the readings cannot fix a parameter or a combination (singular, or a 95 % interval wider than the parameter's usual range, or a coefficient of variation of 100 % or more) |
| `poorly-determined` | a coefficient of variation between 30 % and 100 % |
| `implausible-value` | an estimate outside the usual range for ground |
| `implausible-input` | a value of the case outside the usual range (a unit slip?) |
| `exactly-determined` | as many readings as parameters: χ² cannot test the model |
| `mesh-error` | the mesh's discretisation error on a reading above 0.3 of its sigma |
| `error-scale` | an estimated error scale beyond what the case allows for it (its prior, or the other instruments) |
| `forecast-nonlinear` | a forecast's linearised 95 % band and the range sampled through the model differ by more than 10 % |
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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
    if unit == "kPa" and abs(v) >= 1e3:
        return f"{v / 1e3:.4g} MPa" if abs(v) < 1e6 else f"{v / 1e6:.4g} GPa"
    return f"{v:.4g}" + ("" if unit in ("-", "") else f" {unit}")


def fit_caveats(fit, rel, params, limits, profiled: dict) -> list[Caveat]:
    """Caveats of a fit and its reliability; limits[i] is parameter i's ``Limits`` (or None)."""
    out: list[Caveat] = []
    if fit.status != "converged" and fit.moved:
        out.append(Caveat("not-converged", f"the fit did not converge: {fit.reason}"))
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
        if fit.at_bound[i]:
            lo, hi = params.lower[i], params.upper[i]
            which = lo if abs(p - lo) <= abs(p - hi) else hi
            out.append(Caveat("at-bound", f"{name} ended at its bound {_value(which, unit)}: the readings push it "
                                          f"further (or the bound is wrong); its interval is not meaningful", name))
        lim = limits[i]
        if np.isfinite(sd) and lim is not None:
            positive = lim.lo >= 0
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
                                  f"{name} is not determined by the readings ({_value(p, unit)} ± "
                                  f"{_value(sd, unit)}{f', {100 * cv:.0f} %' if positive else ''}{interval}): no "
                                  f"instrument sees it enough; fix it at a value or give it a prior", name))
            elif positive and cv >= POORLY:
                out.append(Caveat("poorly-determined", f"{name} is poorly determined ({100 * cv:.0f} % coefficient "
                                                       f"of variation)", name))
        if lim is not None and not (lim.plausible[0] <= p <= lim.plausible[1]):
            out.append(Caveat("implausible-value", f"{name} = {_value(p, unit)} is outside the usual range for "
                                                   f"ground ({_value(lim.plausible[0], unit)} to "
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
