"""Reliability of the estimate (eqns 43-55, whitened as in ERRATA.md).

With C_x = L L^t and A' = L^-1 A: C_p = (A'^t A' + C_p0^-1)^-1 (eqn 55), Q = A' C_p A'^t
(information density; symmetric, idempotent without priors, trace = n), the SVD A' = U S V^t
(eqns 44-49) on relative parameter changes dp/p, chi^2 = J_min on m - n degrees of freedom,
and -2 ln L (eqn 5) for AIC and BIC.

Error scales (scales.py): every instrument (or group) gets the scale its readings suggest, with
an interval and the test of its stated sigma. Where scales are estimated, A' and r' are whitened
by them (C_p with the estimated scales), the chi^2 test covers the readings whose sigma is known
(and the priors) on Satterthwaite's degrees of freedom, -2 ln L is the support function (eqn 5)
maximised over the scales, AIC/BIC count them, and the parameters' intervals and ellipse use
Student t / F quantiles on the Satterthwaite degrees of freedom that the scales' uncertainty leaves.
"""
from __future__ import annotations

from dataclasses import dataclass, field


import numpy as np

from geoback.inference import chi2
from geoback.inference import scale_estimates as se
from geoback.inference import scales as sc

Z95 = 1.959963984540054  # standard normal quantile at 0.975
ILL_CONDITIONED = 1e-8  # smallest / largest singular value below which a combination is undetermined


@dataclass
class Reliability:
    names: list[str]
    p: np.ndarray
    covariance: np.ndarray
    std: np.ndarray
    correlation: np.ndarray
    singular_values: np.ndarray  # of A' diag(|p|): sensitivity to relative changes
    directions: np.ndarray  # columns: parameter-space directions V (relative changes)
    condition: float
    information_density: np.ndarray  # Q (m x m)
    leverage: np.ndarray  # diag Q
    whitened_residual: np.ndarray
    chi2: float
    dof: int
    p_value: float
    minus2logL: float
    aic: float
    bic: float
    undetermined: list[str]  # plain-words description of combinations the readings cannot fix
    error_scales: list = field(default_factory=list)  # scales.ScaleEstimate per group of readings
    parameter_dof: np.ndarray | None = None  # Satterthwaite dof of each std (None: every scale known)
    ellipse_dof: float = float("inf")  # denominator dof of the parameters' F ellipse
    total_dof: float = 0  # readings + priors - parameters
    stated_residual: np.ndarray | None = None  # L^-1 (x* - x) with the stated C_x
    stated_J: float = float("nan")  # J with every scale at 1 (data and priors)
    log: np.ndarray | None = None  # parameters identified as ln p: their intervals are made in log space
    information: np.ndarray | None = None  # A'^t A' of the readings alone (no prior rows), physical units

    @property
    def reduced_chi2(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else float("nan")

    @property
    def scales_estimated(self) -> bool:
        return any(e.estimated for e in self.error_scales)

    def interval95(self) -> tuple[np.ndarray, np.ndarray]:
        """Linearised 95 % intervals: p +- z std (z the normal quantile, or Student t's on the
        Satterthwaite dof the estimated error scales leave), for a log-transformed parameter
        exp(ln p +- z std / p) (the same linearisation made where the fit works)."""
        z = np.full(len(self.p), Z95)
        if self.parameter_dof is not None:  # Student t on the dof the estimated scales leave
            from scipy import special

            nu = self.parameter_dof
            z = np.where(np.isfinite(nu), special.stdtrit(np.where(np.isfinite(nu), nu, 1.0), 0.975), z)
        lo, hi = self.p - z * self.std, self.p + z * self.std
        if self.log is not None and np.any(self.log):
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                f = np.exp(z * self.std / np.abs(self.p))
            lo = np.where(self.log, self.p / f, lo)
            hi = np.where(self.log, self.p * f, hi)
        return lo, hi

    def ellipse_limit(self, level: float = 0.95) -> float:
        """d^2 = (p - p_hat)^t C_p^-1 (p - p_hat) below which p is inside the `level` ellipse:
        chi2(n) quantile, or n F(n, nu) with nu = ellipse_dof when scales are estimated."""
        n = len(self.p)
        if np.isfinite(self.ellipse_dof):
            from scipy import special

            return float(n * special.fdtri(n, self.ellipse_dof, level))
        return se.chi2_ppf(level, n)


def chi2_sf(x: float, dof: float) -> float:
    """P(chi^2_dof > x) (geoback.inference.chi2: no scipy.special at start-up)."""
    return chi2.sf(x, dof)


def combination_text(names: list[str], v: np.ndarray) -> str:
    """'dE[clay]/E[clay] - 0.71 dK0/K0' for a direction in relative parameter changes."""
    v = v / v[np.argmax(np.abs(v))]
    parts = []
    for n, c in zip(names, v):
        if abs(c) < 0.05:
            continue
        term = f"d{n}/{n}"
        parts.append(("+ " if c > 0 else "- ") + (f"{abs(c):.2g} " if abs(abs(c) - 1) > 1e-3 else "") + term)
    text = " ".join(parts)
    return text[2:] if text.startswith("+ ") else text


def assess(ev, params, logdet: float) -> Reliability:
    """Everything eqns 43-55 say about the optimum: `ev` is the misfit's Evaluation there (whitened
    residual r' and sensitivity A', prior rows), `logdet` = ln det of the weighting covariance."""
    names, p = params.names, ev.p
    Aw, rw = ev.whitened_sensitivity, ev.whitened_residual
    m, n = Aw.shape
    prec = params.prior_precision()
    scale = np.where(np.abs(p) > 0, np.abs(p), 1.0)
    As = Aw * scale  # sensitivity to relative changes dp/p
    U, s, Vt = np.linalg.svd(As, full_matrices=False)
    cond = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    # the prior adds rows sqrt(C_p0^-1) to the (relative) sensitivity: C_p = (A'^t A' + C_p0^-1)^-1
    aug = np.vstack([As, np.diag(np.sqrt(prec) * scale)])
    _, sa, Vta = np.linalg.svd(aug, full_matrices=False)
    tiny = sa <= ILL_CONDITIONED * sa[0]
    undetermined = [combination_text(names, Vta[i]) for i in np.flatnonzero(tiny)]
    inv2 = np.where(tiny, 0.0, 1.0 / np.where(tiny, 1.0, sa) ** 2)
    Cs = (Vta.T * inv2) @ Vta
    Cp = Cs * np.outer(scale, scale)
    std = np.sqrt(np.clip(np.diag(Cp), 0, None))
    if tiny.any():  # undetermined combinations: their members' std is unbounded
        involved = np.abs(Vta[tiny]).max(axis=0) > 0.05
        std = np.where(involved, np.inf, std)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = Cp / np.outer(std, std)
    corr[~np.isfinite(corr)] = np.nan
    np.fill_diagonal(corr, 1.0)
    Q = As @ Cs @ As.T
    chi2 = ev.J  # data and priors: the priors are observations too (dof counts them)
    dof = m - n + int(np.count_nonzero(prec))
    pval = chi2_sf(chi2, dof)
    m2logL = chi2 + logdet + m * np.log(2 * np.pi)
    groups = tuple(getattr(ev, "groups", ()) or ())
    state = getattr(ev, "scales", None)
    leverage = np.diag(Q).copy()
    if state is None:
        rel = Reliability(list(names), p, Cp, std, corr, s, Vt.T, cond, Q, leverage, rw.copy(), chi2, dof,
                          pval, float(m2logL), float(m2logL + 2 * n), float(m2logL + n * np.log(m)), undetermined,
                          log=np.asarray(params.log, bool), information=Aw.T @ Aw)
        rel.total_dof, rel.stated_residual, rel.stated_J = dof, rel.whitened_residual, chi2
        if groups:  # what each instrument's readings say about its stated sigma
            known = sc.profile_state(groups, rw, np.zeros(len(groups)))
            rel.error_scales = se.group_estimates(known, sc_leverage(groups, leverage))
        return rel
    return _assess_with_scales(ev, params, logdet, groups, state, names, p, Cp, std, corr, s, Vt.T, cond, Q,
                               leverage, aug, Cs, scale, tiny, undetermined, dof)


def sc_leverage(groups, leverage: np.ndarray) -> np.ndarray:
    return np.array([float(leverage[g.rows].sum()) for g in groups])


def _assess_with_scales(ev, params, logdet, groups, state, names, p, Cp, std, corr, s, V, cond, Q, leverage, aug, Cs,
                        scale, tiny, undetermined, total_dof) -> Reliability:
    """The reliability measures when error scales are estimated (see the module docstring)."""
    m, n = ev.m, len(p)
    rw = ev.whitened_residual
    h = sc_leverage(groups, leverage)
    estimates = se.group_estimates(state, h)
    # chi^2 of the readings whose sigma is known, and of the priors, on Satterthwaite's dof:
    # sum r_i^2 over rows R ~ sum of lambda chi2(1), lambda the eigenvalues of (I - Q_full)_RR
    known_rows = np.concatenate([g.rows for g in groups if not g.estimated] or [np.zeros(0, int)]).astype(int)
    prior_rows = m + np.flatnonzero(params.prior_precision() > 0)
    rows = np.concatenate([known_rows, prior_rows]).astype(int)
    prior_r = ev.r[m:]
    chi2 = float(rw[known_rows] @ rw[known_rows] + prior_r @ prior_r)
    if len(rows):
        full = aug @ Cs @ aug.T  # Q over readings and prior rows (relative parameter scaling cancels)
        M = np.eye(len(rows)) - full[np.ix_(rows, rows)]
        t1, t2 = float(np.trace(M)), float(np.sum(M * M))
        dof = t1
        pval = chi2_sf(chi2 * t1 / t2, t1 * t1 / t2) if t1 > 1e-9 else float("nan")
    else:
        dof, pval = 0.0, float("nan")
    # -2 ln L: the support function (eqn 5) maximised over the scales (maximum-likelihood profile)
    n_scales = sum(1 for g in groups if g.estimated)
    m2logL = ev.support + logdet + m * np.log(2 * np.pi)  # support includes m_g u_g and the scales' priors
    # the parameters' dof: Satterthwaite on the estimated scales' uncertainty (var u_g = 2 / nu_g)
    B = ev.whitened_sensitivity
    infos = se.group_information(groups, B)
    nus = np.array([g.information(u, J) if g.estimated else np.inf for g, u, J in zip(groups, state.u, state.J)])
    pdof = se.satterthwaite_dof(Cp, infos, nus) if not tiny.any() else np.full(n, np.inf)
    edof = se.ellipse_dof(h, nus, n)
    stated = ev.stated_residual
    k = n + n_scales
    rel = Reliability(list(names), p, Cp, std, corr, s, V, cond, Q, leverage, rw.copy(), chi2, dof, pval,
                      float(m2logL), float(m2logL + 2 * k), float(m2logL + k * np.log(m)), undetermined,
                      estimates, pdof, edof, total_dof, stated, float(stated @ stated + prior_r @ prior_r),
                      log=np.asarray(params.log, bool), information=B.T @ B)
    return rel

