"""What an error scale means: intervals of k, tests of the stated sigma, the words of the report,
and the degrees of freedom the estimated scales leave the parameters (``scales.py`` profiles the
scales; this module judges them; see its docstring for the formulas)."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from geoback.inference import chi2
from geoback.inference.scales import LEVEL, MIN_DOF_REPORTED, ScaleGroup, ScaleState, special_scales

# ---------------------------------------------------------------------------- what it means
@dataclass(frozen=True)
class ScaleEstimate:
    """One group's error scale: k = true sigma / stated sigma, with its interval and tests (a
    frozen value, built complete by ``group_estimates``; the fields' formulas are given there and
    in ``factor_interval``, ``stated_p``, ``prior_predictive_p`` and ``others_p``)."""

    name: str
    instruments: tuple[str, ...]
    treatment: str  # known | estimated | estimated, <shape> prior (...)
    estimated: bool
    readings: int
    dof: float  # c_g = m_g - h_g
    factor: float  # k used for C_p (1 for known groups)
    low: float
    high: float  # interval of k (level): of the readings alone for known groups
    readings_factor: float  # what the readings alone say: sqrt(J_g / c_g)
    p_stated: float  # two-sided test of k = 1 (J_g ~ chi2(c_g))
    p_allowed: float  # upper tail: prior-predictive (with a prior) or F against the others (without)
    allowed_test: str  # "prior" | "others" | ""
    ratio_to_others: float  # sqrt of the F statistic (scale without a prior), nan otherwise
    J: float
    text: str = ""
    level: float = LEVEL

    def as_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


def chi2_cdf(x: float, dof: float) -> float:
    return chi2.cdf(x, dof)


def chi2_ppf(q: float, dof: float) -> float:
    return chi2.ppf(q, dof)


def _log_posterior_interval(g: ScaleGroup, J: float, c: float, u_hat: float, level: float) -> tuple[float, float]:
    """Interval of u from the density exp(-f(u)/2) by quadrature (any prior; exact in 1-D)."""
    sd = math.sqrt(2 / max(g.information(u_hat, J), 1e-12))
    u = np.linspace(u_hat - 14 * sd, u_hat + 14 * sd, 4001)
    f = np.array([g.objective(v, J, c) for v in u])
    dens = np.exp(-(f - f.min()) / 2)
    cdf = np.concatenate([[0.0], np.cumsum((dens[1:] + dens[:-1]) / 2 * np.diff(u))])
    cdf /= cdf[-1]
    a = (1 - level) / 2
    return float(np.interp(a, cdf, u)), float(np.interp(1 - a, cdf, u))


def factor_interval(g: ScaleGroup, J: float, c: float, u_hat: float, level: float = LEVEL) -> tuple[float, float]:
    """Interval of k: J/phi ~ chi2(c) (no prior, or a known group's readings alone),
    (J + nu0)/phi ~ chi2(c + nu0) (inverse-chi2), quadrature of the posterior (log-normal)."""
    a = (1 - level) / 2

    def root(x: float, q: float) -> float:
        return math.sqrt(x / q) if q > 0 else math.inf

    if g.kind in ("known", "free"):
        if not c > MIN_DOF_REPORTED:
            return float("nan"), float("nan")
        return root(J, chi2_ppf(1 - a, c)), root(J, chi2_ppf(a, c))
    if g.kind == "inverse-chi2":
        d = c + g.nu0
        return root(J + g.nu0, chi2_ppf(1 - a, d)), root(J + g.nu0, chi2_ppf(a, d))
    lo, hi = _log_posterior_interval(g, J, c, u_hat, level)
    return math.exp(lo / 2), math.exp(hi / 2)


def stated_p(J: float, c: float) -> float:
    """Two-sided p of k = 1: J ~ chi2(c)."""
    if not c > MIN_DOF_REPORTED:
        return float("nan")
    lower, upper = chi2.cdf(J, c), chi2.sf(J, c)
    return float(min(1.0, 2 * min(lower, upper)))


def prior_predictive_p(g: ScaleGroup, J: float, c: float) -> float:
    """P(J_pred >= J) when phi comes from the prior and J_pred = phi chi2(c): do the readings
    ask for a larger scale than the prior allows?"""
    if c <= 0:
        return float("nan")
    if g.kind == "inverse-chi2":
        return float(special_scales().fdtrc(c, g.nu0, J / c))
    if g.kind == "lognormal":  # Gauss-Hermite over u ~ N(0, 4 tau^2)
        x, w = np.polynomial.hermite_e.hermegauss(64)
        u = 2 * g.tau * x
        return float(np.sum(w * special_scales().gammaincc(c / 2, J * np.exp(-u) / 2)) / math.sqrt(2 * math.pi))
    return float("nan")


def others_p(J: float, c: float, J_rest: float, c_rest: float) -> tuple[float, float]:
    """F test of a group's scale against the pooled scale of the other readings (one-sided,
    upper): (ratio of the scales k_g / k_rest, p)."""
    if c <= 0 or c_rest <= 0 or J_rest <= 0:
        return float("nan"), float("nan")
    F = (J / c) / (J_rest / c_rest)
    return math.sqrt(F), float(special_scales().fdtrc(c, c_rest, F))


def _p(p: float) -> str:
    """'p = 0.012' (or 'p < 1e-300' where it underflows)."""
    if not np.isfinite(p):
        return "p = nan"
    return f"p = {p:.2g}" if p > 0 else "p < 1e-300"


def _k(v: float) -> str:
    """A factor as people write it: 3.4, 1.0, 0.64, 12."""
    return f"{v:.1f}" if 1 <= v < 10 else f"{v:.2g}"


def describe(e: ScaleEstimate) -> str:
    """The plain-words line of one group's scale."""
    lv = f"{100 * e.level:g} %"
    who = e.name
    if not np.isfinite(e.p_stated):
        return f"{who}: too few readings beyond the parameters to judge its stated σ"
    consistent = e.p_stated >= 1 - e.level
    verdict = (f"consistent with the stated σ ({_p(e.p_stated)})" if consistent else
               f"the stated σ is not consistent with its readings ({_p(e.p_stated)})")
    if e.estimated:
        text = (f"{who}'s errors are {_k(e.factor)}× what the case states ({lv} [{e.low:.2g}, {e.high:.2g}]); "
                f"{verdict}")
        if e.allowed_test == "prior" and e.p_allowed < 1 - e.level:
            text += (f"; its readings alone ask for {_k(e.readings_factor)}×, more than its prior allows "
                     f"({_p(e.p_allowed)})")
        elif e.allowed_test == "others" and e.p_allowed < 1 - e.level:
            text += (f"; {_k(e.ratio_to_others)}× the other instruments' scale ({_p(e.p_allowed)}): "
                     f"either {who} was read less accurately than stated or the model misses something "
                     f"that shows at {who}")
        return text
    return (f"{who}: σ taken as stated; its readings alone suggest {_k(e.readings_factor)}× ({lv} [{e.low:.2g}, "
            f"{e.high:.2g}]), {verdict}")


def group_estimates(state: ScaleState, h: np.ndarray, level: float = LEVEL) -> list[ScaleEstimate]:
    """Every group's scale with its interval and tests at the optimum (h: leverage by group, with
    the estimated scales; the dof reported is c_g = m_g - h_g)."""
    out = []
    J_all = float(state.J.sum())
    for k, g in enumerate(state.groups):
        J = float(state.J[k])
        c = float(g.m - h[k])
        if c < MIN_DOF_REPORTED:  # every reading taken up by the parameters (round-off included)
            c = 0.0
        readings = math.sqrt(J / c) if c > 0 else float("nan")
        if g.estimated:
            u = g.profile(J, c) if (c > 0 or g.has_prior) else float("nan")
            factor = math.exp(u / 2)
            lo, hi = factor_interval(g, J, c, u, level) if np.isfinite(u) else (float("nan"),) * 2
        else:
            factor = 1.0
            lo, hi = factor_interval(g, J, c, 0.0, level) if c > 0 else (float("nan"),) * 2
        ratio, test, p_allowed = float("nan"), "", float("nan")
        if g.has_prior:
            test, p_allowed = "prior", prior_predictive_p(g, J, c)
        elif g.estimated and len(state.groups) > 1:
            c_rest = float(sum(state.groups[j].m - h[j] for j in range(len(state.groups)) if j != k))
            ratio, p_allowed = others_p(J, c, J_all - J, c_rest)
            test = "others"
        e = ScaleEstimate(g.name, g.instruments, g.treatment(), g.estimated, g.m, c, factor, lo, hi, readings,
                          stated_p(J, c), p_allowed, test, ratio, J, level=level)
        out.append(replace(e, text=describe(e)))
    return out


# ---------------------------------------------------------------------------- parameters' dof
def group_information(groups, Bw: np.ndarray) -> list[np.ndarray]:
    """B_g^t B_g of each group (whitened with the estimated scales)."""
    return [Bw[g.rows].T @ Bw[g.rows] for g in groups]


def satterthwaite_dof(Cp: np.ndarray, infos: list[np.ndarray], nus: np.ndarray) -> np.ndarray:
    """Effective degrees of freedom of each parameter's variance v_j = (C_p)_jj when the scales
    are estimated: dv_j/du_g = (C_p I_g C_p)_jj, var(u_g) = 2 / nu_g, nu_j = v_j^2 / sum_g
    (dv_j/du_g)^2 / nu_g (inf when every scale is known)."""
    v = np.diag(Cp)
    den = np.zeros_like(v)
    for I_g, nu in zip(infos, nus):
        if np.isfinite(nu):
            d = np.diag(Cp @ I_g @ Cp)
            den += d * d / nu
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, v * v / np.where(den > 0, den, 1.0), np.inf)


def ellipse_dof(h: np.ndarray, nus: np.ndarray, n: int) -> float:
    """Denominator dof nu of the ellipse d^2 = e^t C_p^-1 e ~ n F(n, nu). With C_p^-1 = sum_g
    I_g / phi_g (+ priors) and phi_g / phi_hat_g ~ nu_g / chi2(nu_g) independent of e,
    E[d^2] = sum_g h_g nu_g / (nu_g - 2) (h_g = tr(C_p I_g), the group's leverage; known groups and
    priors with factor 1), matched to the mean n nu / (nu - 2) of n F(n, nu)."""
    est = np.isfinite(nus) & (h > 1e-9)
    if not est.any():
        return math.inf
    if np.any(nus[est] <= 2.05):
        return float(max(nus[est].min(), 0.5))
    inflation = h[est] * nus[est] / (nus[est] - 2) - h[est]  # the known readings and priors add their h
    E = n + float(inflation.sum())
    return math.inf if E <= n * (1 + 1e-12) else 2 * E / (E - n)
