"""Intervals that allow for their selection (issue 24): a cause is reported because its likelihood-
ratio test passed its round's level, so near that detection limit the causes reported are those whose
noise happened to enlarge them, and their usual 95 % interval holds the truth less often than 95 % (the
winner's curse; measured in the diagnosis benchmarks).

For a cause with ONE extra parameter theta (null value theta0: the model without the cause), the
refit's likelihood-ratio statistic is dJ ~ chi^2_1 under the null, and in the linear approximation

    z = sign(theta_hat - theta0) sqrt(dJ) ~ N(mu, 1),   mu = (theta - theta0) / sigma,
    (for a linear model z = (theta_hat - theta0) / sigma and the usual interval is theta_hat +- 1.96 sigma).

The cause was accepted when |z| > c, c^2 the chi^2_1 quantile at its round's level (alpha over the
Bonferroni family, ``Round.threshold``). Given that it was, z follows N(mu, 1) truncated to |z| > c,
whose upper tail

    G_mu(z) = P(Z > z | |Z| > c) = Phi(mu - z) / [Phi(-c - mu) + Phi(mu - c)]      (z > c)

grows with mu. The selection-adjusted 95 % interval for mu is {mu : 0.025 <= G_mu(z_obs) <= 0.975}, found
by root finding on log G (Lee, Sun, Sun & Taylor 2016, Ann. Statist. 44(3), sec. 5: one truncation region
of a Gaussian statistic; Fithian, Sun & Taylor 2014). Each end moves from the usual one, z -+ 1.96, by
d_lo = mu_lo - (z - 1.96) and d_hi = mu_hi - (z + 1.96); the reported interval's ends (linearised or
profile likelihood, as the verdict has them) move by the same amounts in units of that side's half-width
/ 1.96 (exact for a linear model; a profile interval keeps its asymmetry). The statistic is the refit's
own dJ, not (theta_hat - theta0) / std: in a non-linear model the two differ (measured: a stiffness
gradient accepted at dJ = 18.5, z = 4.3, had estimate / std = 2.9). The interval holds the truth in 95 %
of the causes accepted, whatever the effect's size (tested by Monte Carlo on the linear model); far above
the limit (|z| - c >> 2) it is the usual one; just above it, it widens towards the null value and may
contain it (the readings then say a cause is there, but not how large it is).

What it does not allow for: the other checks a cause passes (claim checks, the score-test ranking
that chose which hypotheses were refitted), a later round changing the estimate, and the non-linearity
of the refit (the statistic is taken from the final joint fit, as the interval is). Causes with more than
one extra parameter (a stratum's modulus and depth) get none: said so where they are reported.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize, special

LEVEL = 0.95
NOTICEABLE = 0.05  # an adjusted end this far (in half-widths of the usual interval) from the usual one is shown


@dataclass(frozen=True)
class SelectiveInterval:
    """The selection-adjusted interval of one parameter: its ends (low, high), the statistic z and the
    level c it was accepted at (|z| > c), and whether it differs noticeably from the usual interval."""

    low: float
    high: float
    z: float
    c: float
    noticeable: bool

    def as_dict(self) -> dict:
        return {"ci95": [self.low, self.high], "z": self.z, "accepted_above": self.c, "differs": self.noticeable}


def _log_upper_tail(mu: float, z: float, c: float) -> float:
    """log G_mu(z) for z > c (the truncated normal's upper tail at z)."""
    num = special.log_ndtr(mu - z)
    den = np.logaddexp(special.log_ndtr(-c - mu), special.log_ndtr(mu - c))
    return float(num - den)


def mu_interval(z: float, c: float, level: float = LEVEL) -> tuple[float, float]:
    """The interval for mu of N(mu, 1) truncated to |Z| > c, at an observed z with |z| > c (see the module
    docstring); symmetric in the sign of z."""
    if not (np.isfinite(z) and np.isfinite(c) and c >= 0 and abs(z) > c):
        raise ValueError(f"expected |z| > c >= 0, found z = {z!r}, c = {c!r}")
    sign, z = (1.0, z) if z > 0 else (-1.0, -z)  # by symmetry: z > c
    a = 0.5 * (1 - level)

    def f(mu, target):
        return _log_upper_tail(mu, z, c) - math.log(target)

    ends = []
    for target in (a, 1 - a):  # G = a at the lower end, 1 - a at the upper end (G grows with mu)
        lo, hi = z - 10.0, z + 10.0
        while f(lo, target) > 0:
            lo -= 10.0 + (z - lo)
        while f(hi, target) < 0:
            hi += 10.0
        ends.append(optimize.brentq(f, lo, hi, args=(target,), xtol=1e-10, rtol=1e-12))
    low, high = ends
    return (low, high) if sign > 0 else (-high, -low)


def critical_value(level: float) -> float:
    """c with P(|Z| > c) = level: the |z| a one-parameter refit needs to be accepted at that level."""
    return float(-special.ndtri(0.5 * level))


def selective_interval(estimate: float, low: float, high: float, statistic: float, null: float,
                       level_accepted: float) -> SelectiveInterval | None:
    """The selection-adjusted 95 % interval of a one-parameter cause accepted at `level_accepted` (its
    round's per-hypothesis level) on the likelihood-ratio `statistic` dJ of its refit, from the reported
    interval (low, high) around `estimate` (see the module docstring). None where it is not defined: an
    interval not finite or not around the estimate, or the statistic not beyond the acceptance limit. It
    differs noticeably from the usual interval when an end moves by more than NOTICEABLE of its half-width."""
    if not (np.isfinite(estimate) and np.isfinite(low) and np.isfinite(high) and low <= estimate <= high
            and np.isfinite(statistic) and statistic > 0 and 0 < level_accepted < 1 and estimate != null):
        return None
    z = math.copysign(math.sqrt(statistic), estimate - null)
    c = critical_value(level_accepted)
    if not abs(z) > c:
        return None
    m_lo, m_hi = mu_interval(z, c)
    q = float(-special.ndtri(0.5 * (1 - LEVEL)))
    d_lo, d_hi = m_lo - (z - q), m_hi - (z + q)
    lo = low + d_lo * (estimate - low) / q
    hi = high + d_hi * (high - estimate) / q
    noticeable = max(abs(d_lo), abs(d_hi)) > NOTICEABLE * q
    return SelectiveInterval(float(lo), float(hi), float(z), c, bool(noticeable))
