"""Profile-likelihood intervals (as lmfit's ``conf_interval``): the values of one parameter at which
J, minimised over the others, rises by chi^2_1(95 %) = 3.84 above its minimum.

Used where the linearised interval of eqn (55) is not reliable: a large coefficient of variation, an
interval that crosses a bound or the physically allowed range, or an objective that is far from
quadratic along the parameter; or when asked for. Each point of a profile is a fit of the other
parameters (their factorisations reused), so a profile costs a few dozen fast fits. Where the model
has no solution (a Mohr-Coulomb run that does not converge) the end is open, at the parameter's
limit; once the time limit has passed (``geoback.case.budget``) an end not yet found is the linearised one.
"""
from __future__ import annotations

import numpy as np
from scipy import optimize

from geoback.case import budget
from geoback.errors import ForwardFailure
from geoback.inference.estimate import Settings, fit

CHI2_1_95 = 3.841458820694124
MAX_STEPS = 40


class _Profile:
    """J minimised over the other parameters with parameter i held, each fit started from the
    nearest point already profiled (continuation: a few iterations each)."""

    def __init__(self, misfit, settings: Settings, i: int, p_hat: np.ndarray):
        self.misfit, self.settings, self.i = misfit, settings, i
        self.done = [(float(p_hat[i]), np.delete(p_hat, i))]
        self.fits = 0

    def __call__(self, value: float) -> float:
        if self.misfit.n == 1:
            return self.misfit.J(np.array([value]))
        start = min(self.done, key=lambda d: abs(d[0] - value))[1]
        f = fit(self.misfit.holding(self.i, value), self.settings, p0=start, max_iterations=50)
        self.fits += 1
        self.done.append((value, f.p))
        return f.J


def profile_interval(misfit, settings: Settings, p_hat: np.ndarray, J_min: float, i: int, std: float,
                     lo_limit: float, hi_limit: float, log: bool) -> tuple[float, float]:
    """95 % profile-likelihood interval of parameter i; an end that reaches its limit (a bound or
    the allowed range) without J rising enough is that limit (then the interval is open there).
    Ends are found to 1e-4 of the parameter's size (four significant digits)."""
    target = J_min + CHI2_1_95
    x0 = float(p_hat[i])
    J = _Profile(misfit, settings, i, p_hat)
    seen: dict = {}  # each value's profile once: a fit from another start could land elsewhere (loose
    # tolerances), and the root search must see the signs the search outwards saw

    def g(v):
        v = float(v)
        if v not in seen:
            seen[v] = J(v) - target
        return seen[v]

    ends = []
    for sign in (-1.0, 1.0):
        limit = lo_limit if sign < 0 else hi_limit
        # first try the linearised end, then step outwards (in ln p for positive parameters), faster and faster
        half = 1.96 * std if np.isfinite(std) and std > 0 else 0.1 * max(abs(x0), 1e-12)
        if log and x0 > 0:
            step = np.log1p(min(half / x0, 20.0))
            at = (lambda t: x0 * np.exp(sign * step * t))
        else:
            at = (lambda t: x0 + sign * half * t)
        inside, end = x0, None
        linearised = float(np.clip(x0 + sign * half, min(lo_limit, hi_limit), max(lo_limit, hi_limit)))
        for k in range(MAX_STEPS):
            if budget.expired("a profile-likelihood interval"):  # the linearised end: the best there is now
                end = linearised
                break
            v = at(1.5 ** k)
            if (sign < 0 and v <= limit) or (sign > 0 and v >= limit):
                v = limit
            try:
                if g(v) >= 0:
                    if g(inside) >= 0:  # not below the target where the search came from: J_min is not this
                        # misfit's minimum (a fit stopped by a loose tolerance): the linearised end at the estimate
                        end = linearised if inside == x0 else inside
                    else:
                        end = optimize.brentq(g, min(inside, v), max(inside, v), xtol=1e-4 * max(abs(x0), 1e-12),
                                              rtol=1e-6)
                    break
            except ForwardFailure:  # no solution at v (or between): the profile did not see the readings bound
                end = limit  # it there; the end is open (at its limit) rather than a bound it did not see
                break
            inside = v
            if v == limit:
                end = limit
                break
        ends.append(end if end is not None else inside)
    return ends[0], ends[1]

