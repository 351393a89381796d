"""Profile-likelihood intervals (as lmfit's ``conf_interval``): the values of one parameter at which
J, minimised over the others, rises by chi^2_1(95 %) = 3.84 above its minimum.

Used where the linearised interval of eqn (55) is not reliable: a large coefficient of variation, an
interval that crosses a bound or the physically allowed range, or an objective that is far from
quadratic along the parameter; or when asked for. Each point of a profile is a fit of the other
parameters (their factorisations reused), so a profile costs a few dozen fast fits.
"""
from __future__ import annotations

import numpy as np
from scipy import optimize

from .estimate import Settings, fit

CHI2_1_95 = 3.841458820694124
MAX_STEPS = 40


def _profile_J(misfit, settings: Settings, i: int, value: float, start: np.ndarray) -> float:
    """min over the other parameters of J with parameter i held at `value`."""
    if misfit.n == 1:
        return misfit.J(np.array([value]))
    held = misfit.holding(i, value)
    return fit(held, settings, p0=np.delete(start, i), max_iterations=50).J


def profile_interval(misfit, settings: Settings, p_hat: np.ndarray, J_min: float, i: int, std: float,
                     lo_limit: float, hi_limit: float, log: bool) -> tuple[float, float]:
    """95 % profile-likelihood interval of parameter i; an end that reaches its limit (a bound or
    the allowed range) without J rising enough is that limit (then the interval is open there)."""
    target = J_min + CHI2_1_95
    x0 = float(p_hat[i])

    def g(v):
        return _profile_J(misfit, settings, i, v, p_hat) - target

    ends = []
    for sign in (-1.0, 1.0):
        limit = lo_limit if sign < 0 else hi_limit
        # step outwards, in ln p for positive parameters, starting at a third of the linearised half-width
        if log and x0 > 0:
            step = np.log1p(min(max(std / x0, 1e-4), 5.0) * 1.96 / 3) if np.isfinite(std) else 0.1
            at = (lambda k: x0 * np.exp(sign * step * k))
        else:
            step = (1.96 * std / 3) if np.isfinite(std) and std > 0 else max(abs(x0), 1.0) * 0.05
            at = (lambda k: x0 + sign * step * k)
        inside, end = x0, None
        for k in range(1, MAX_STEPS + 1):
            v = at(2 ** (k // 4) * k)  # a little faster the further it goes
            if (sign < 0 and v <= limit) or (sign > 0 and v >= limit):
                v = limit
            if g(v) >= 0:
                end = optimize.brentq(g, min(inside, v), max(inside, v), xtol=1e-6 * max(abs(x0), 1e-12), rtol=1e-6)
                break
            inside = v
            if v == limit:
                end = limit
                break
        ends.append(end if end is not None else inside)
    return ends[0], ends[1]
