"""Error scales: how well each instrument's stated sigma is known (paper eqns 5 and 10).

Each instrument's covariance is C_x,i = sigma_i^2 E_x,i (eqn 10): the case states C_x,i and may
say that the stated size is right only up to a factor k (the true sigma is k times the stated
one). Instruments are put in *groups* (one instrument, or several sharing one k); write
u = ln k^2 = ln phi for a group's log variance factor. With r' = L^-1 (x* - x) whitened by the
stated C_x and J_g = sum of r'^2 over the group's readings, the group's part of the support
function S = -2 ln L (eqn 5, with ln|C_x|) is

    J_g e^-u + m_g u   (+ ln|C_x,g stated| + m_g ln 2 pi, constants)

and a prior on k adds pi(u) = -2 ln(prior density of u), shifted to pi(0) = 0:

    log-normal:    ln k ~ N(0, tau^2)               pi(u) = u^2 / (4 tau^2)
    inverse-chi2:  k^2 ~ scaled-inv-chi2(nu0, 1)    pi(u) = nu0 (u + e^-u - 1)

('within a factor f' sets tau or nu0 so that the prior gives probability `level` to 1/f <= k <= f.)

Profile at fixed parameters. For a group with c_g degrees of freedom the objective

    f_g(u) = J_g e^-u + c_g u + pi(u)

is minimised in closed form: u = ln(J_g / c_g) (no prior), ln((J_g + nu0) / (c_g + nu0))
(inverse-chi2: the prior counts as nu0 readings of scale 1) and u = W(a J_g e^(a c_g)) - a c_g with
a = 2 tau^2 and W Lambert's function (log-normal). The parameters' objective is then

    S*(p) = sum over known groups J_g(p) + prior rows + sum over estimated groups min_u f_g(u; J_g(p)),

which equals J(p) when every scale is 1 and whose gradient is that of J with each group's rows
whitened by its estimated scale (envelope theorem): Gauss-Newton needs only the re-weighted
residuals and sensitivities, no new solves (``misfit.Misfit.evaluate``).

Restricted (REML) degrees of freedom. With c_g = m_g the profile is plain maximum likelihood,
whose scales are biased low by the parameters' degrees of freedom (sigma^2 = J / m instead of
J / (m - n) in ordinary least squares); with few readings per instrument (the paper's extensometer
has 5) that bias makes C_p too small. geoback uses the restricted likelihood of the linearised
model instead: adding ln|A'^t Phi^-1 A' + C_p0^-1| to S and differentiating in u_g gives the same
closed form with

    c_g = m_g - h_g,     h_g = sum over the group's readings of the leverage Q_ii,

Q = A' C_p A'^t whitened with the estimated scales (the group's share of the n parameters). h_g
depends on the scales, so c is the fixed point of c -> h(phi(c)) at the optimum: the misfit
computes it there (``Misfit.anchored``) and the fit is repeated from the optimum until c stops
changing (two or three rounds, the later ones one iteration each). For the parameters this is
generalised least squares with the restricted scale estimates, as in mixed models.

Likelihood comparisons (-2 ln L, AIC, BIC, diagnose's likelihood-ratio tests between models with
different parameters) use the maximum-likelihood profile (c_g = m_g): restricted likelihoods of
different mean models cannot be compared.

Intervals and tests (``group_estimates``): the interval of k from the restricted distribution of
the scale (J_g / phi ~ chi2(c_g) without a prior; (J_g + nu0) / phi ~ chi2(c_g + nu0) with the
inverse-chi2 prior; the log-normal posterior by quadrature); the test of the stated sigma (k = 1:
J_g ~ chi2(c_g), two-sided); for a scale with a prior, the prior-predictive test of whether the
readings ask for more than the prior allows; for a scale without a prior, the F test of its scale
against the pooled scale of every other instrument (a scale far above the others' is a located
mismatch, see ``diagnosis.procedure``). The parameters' intervals account for the scales being
estimated with Satterthwaite degrees of freedom (``satterthwaite_dof``, ``ellipse_dof``); these
live in ``scale_estimates.py``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def special_scales():
    """scipy.special, loaded when first needed (it costs a fifth of a second at start-up, and a case
    without estimated scales never needs it)."""
    from scipy import special

    return special

KINDS = ("known", "free", "lognormal", "inverse-chi2")
MIN_DOF = 1.0  # degrees of freedom an estimated scale without a prior needs after the parameters
MIN_DOF_REPORTED = 1e-6  # below this a group has no readings left to judge its stated sigma
LEVEL = 0.95


# ---------------------------------------------------------------------------- groups
@dataclass(frozen=True)
class ScaleGroup:
    """Readings sharing one factor k on their stated sigma. kind: 'known' (k = 1), 'free'
    (estimated), 'lognormal' or 'inverse-chi2' (estimated with that prior on k)."""

    name: str
    instruments: tuple[str, ...]
    rows: np.ndarray  # indices of the group's readings in survey order
    kind: str = "known"
    tau: float = math.inf  # log-normal prior: std of ln k
    nu0: float = 0.0  # inverse-chi2 prior: its degrees of freedom
    within: float | None = None  # the case's 'within a factor' (for the words)
    at: tuple | None = None  # where the group is in the case file (located errors)

    @property
    def m(self) -> int:
        return len(self.rows)

    @property
    def estimated(self) -> bool:
        return self.kind != "known"

    @property
    def has_prior(self) -> bool:
        return self.kind in ("lognormal", "inverse-chi2")

    def treatment(self) -> str:
        if self.kind == "known":
            return "known"
        if self.kind == "free":
            return "estimated"
        what = f"within a factor {self.within:g}" if self.within else f"{self.nu0:g} dof"
        return f"estimated, {self.kind} prior ({what})"

    # -- the prior on u = ln k^2, shifted to pi(0) = 0, and its derivatives
    def penalty(self, u: float) -> float:
        if self.kind == "lognormal":
            return u * u / (4 * self.tau ** 2)
        if self.kind == "inverse-chi2":
            return self.nu0 * (u + math.exp(-u) - 1.0)
        return 0.0

    def penalty_d1(self, u: float) -> float:
        if self.kind == "lognormal":
            return u / (2 * self.tau ** 2)
        if self.kind == "inverse-chi2":
            return self.nu0 * (1.0 - math.exp(-u))
        return 0.0

    def penalty_d2(self, u: float) -> float:
        if self.kind == "lognormal":
            return 1 / (2 * self.tau ** 2)
        if self.kind == "inverse-chi2":
            return self.nu0 * math.exp(-u)
        return 0.0

    # -- the profile
    def objective(self, u: float, J: float, c: float) -> float:
        """f(u) = J e^-u + c u + pi(u)."""
        return J * math.exp(-u) + c * u + self.penalty(u)

    def profile(self, J: float, c: float) -> float:
        """argmin_u f(u) in closed form (see the module docstring)."""
        J = max(float(J), 1e-300)
        if self.kind == "known":
            return 0.0
        if self.kind == "free":
            return math.log(J / c)
        if self.kind == "inverse-chi2":
            return math.log((J + self.nu0) / (c + self.nu0))
        a = 2 * self.tau ** 2
        return lambert_w_exp(math.log(a * J) + a * c) - a * c

    def information(self, u: float, J: float) -> float:
        """f''(u): half the inverse variance of u, i.e. the degrees of freedom nu_g with
        var(u) = 2 / nu_g (= c_g without a prior, c_g + nu0 with the inverse-chi2 prior)."""
        return J * math.exp(-u) + self.penalty_d2(u)


def lambert_w_exp(x: float) -> float:
    """W(e^x), the solution w > 0 of w + ln w = x, without overflowing e^x (Newton in log form)."""
    if x < -700:
        return math.exp(x)
    w = x - math.log(x) if x > 1.0 else math.exp(x) / (1.0 + math.exp(x)) + 0.5 * max(x, 0.0)
    w = max(w, 1e-300)
    for _ in range(100):
        step = w * (x - w - math.log(w)) / (1.0 + w)
        w_new = max(w + step, w / 10)
        if abs(w_new - w) <= 1e-15 * max(w_new, 1e-300):
            return w_new
        w = w_new
    return w


def lognormal_tau(within: float, level: float = LEVEL) -> float:
    """std of ln k giving probability `level` to 1/within <= k <= within."""
    return math.log(within) / float(special_scales().ndtri(0.5 + level / 2))


def inverse_chi2_dof(within: float, level: float = LEVEL) -> float:
    """nu0 of k^2 ~ scaled-inv-chi2(nu0, 1) giving probability `level` to 1/within <= k <= within:
    P(nu0 / f^2 <= chi2(nu0) <= nu0 f^2) = level (increasing in nu0), by bisection in ln nu0."""
    f2 = within * within

    def mass(nu):
        return float(special_scales().gammainc(nu / 2, nu * f2 / 2) - special_scales().gammainc(nu / 2, nu / f2 / 2))

    lo, hi = 1e-8, 1e8
    if mass(hi) < level:
        return hi
    if mass(lo) > level:
        return lo
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if mass(mid) < level else (lo, mid)
        if hi / lo < 1 + 1e-12:
            break
    return math.sqrt(lo * hi)


def groups_of(case, blocks) -> tuple[ScaleGroup, ...]:
    """The case's error_scales entries as groups of reading rows (every instrument not listed is
    its own known group), in the order of their first reading."""
    spans, start = {}, 0
    for b in blocks:  # an instrument read at several construction stages has several blocks
        spans.setdefault(b.name, []).append(np.arange(start, start + b.m))
        start += b.m
    rows = {name: np.concatenate(parts) for name, parts in spans.items()}
    out, listed = [], set()
    for i, entry in enumerate(getattr(case, "error_scales", None) or []):
        names = tuple(entry.instruments)
        listed.update(names)
        kind, tau, nu0, within = "known", math.inf, 0.0, None
        if entry.scale == "estimate":
            kind = "free"
            if entry.prior is not None:
                pr = entry.prior
                kind = pr.shape
                within = pr.within
                if pr.shape == "lognormal":
                    tau = lognormal_tau(pr.within, pr.level)
                else:
                    nu0 = float(pr.dof) if pr.dof is not None else inverse_chi2_dof(pr.within, pr.level)
        idx = np.concatenate([rows[n] for n in names if n in rows]) if names else np.zeros(0, int)
        out.append(ScaleGroup(entry.name or "+".join(names), names, np.sort(idx), kind, tau, nu0, within,
                              ("error_scales", i)))
    for name in rows:
        if name not in listed:
            out.append(ScaleGroup(name, (name,), rows[name]))
    return tuple(sorted(out, key=lambda g: int(g.rows[0]) if g.m else 1 << 62))


def default_groups(blocks) -> tuple[ScaleGroup, ...]:
    """One known group per instrument (a case without error_scales)."""
    return groups_of(None, blocks)


# ---------------------------------------------------------------------------- state at p
@dataclass(frozen=True)
class ScaleState:
    """The scales profiled at one p: per group J_g (stated whitening), the dof c_g used and the
    log variance factor u_g (0 for known groups); `row_u` spreads u over the readings."""

    groups: tuple[ScaleGroup, ...]
    J: np.ndarray
    c: np.ndarray
    u: np.ndarray
    row_u: np.ndarray
    objective: float  # sum of min_u f_g over estimated groups + J of known groups (no prior rows)
    support: float  # the same with the maximum-likelihood profile (c_g = m_g)

    @property
    def factor(self) -> np.ndarray:
        """k = sigma / stated sigma of each group."""
        return np.exp(self.u / 2)


def profile_state(groups, rw: np.ndarray, c: np.ndarray) -> ScaleState:
    """Profile every estimated group's scale at the stated-whitened residual rw."""
    J = np.array([float(rw[g.rows] @ rw[g.rows]) for g in groups])
    u = np.zeros(len(groups))
    obj = sup = 0.0
    for k, g in enumerate(groups):
        if not g.estimated:
            obj += J[k]
            sup += J[k]
            continue
        u[k] = g.profile(J[k], c[k])
        obj += g.objective(u[k], J[k], c[k])
        sup += g.objective(g.profile(J[k], g.m), J[k], g.m)
    row_u = np.zeros(len(rw))
    for k, g in enumerate(groups):
        row_u[g.rows] = u[k]
    return ScaleState(tuple(groups), J, np.asarray(c, float), u, row_u, float(obj), float(sup))


def initial_dof(groups, n: int) -> np.ndarray:
    """Starting c_g: the n parameters' degrees of freedom shared in proportion to the readings."""
    m = sum(g.m for g in groups)
    return np.array([max(g.m * (1 - n / m), 0.5) if m else 1.0 for g in groups])


def leverage_by_group(groups, Bw: np.ndarray, m: int) -> np.ndarray:
    """h_g = sum of diag Q over each group's readings, Q = B (B^t B)^+ B^t (B: whitened
    sensitivity with the prior rows appended; only the first m rows are readings)."""
    U, s, _ = np.linalg.svd(Bw, full_matrices=False)
    keep = s > 1e-10 * (s[0] if len(s) else 1.0)
    q = np.sum(U[:m, keep] ** 2, axis=1)
    return np.array([float(q[g.rows].sum()) for g in groups])
