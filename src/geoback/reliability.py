"""Reliability of the estimate (eqns 43-55, whitened as in ERRATA.md).

With C_x = L L^t and A' = L^-1 A: C_p = (A'^t A' + C_p0^-1)^-1 (eqn 55), Q = A' C_p A'^t
(information density; symmetric, idempotent without priors, trace = n), the SVD A' = U S V^t
(eqns 44-49) on relative parameter changes dp/p, chi^2 = J_min on m - n degrees of freedom,
and -2 ln L (eqn 5) for AIC and BIC.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

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
    log: np.ndarray | None = None  # parameters identified as ln p: their intervals are made in log space

    @property
    def reduced_chi2(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else float("nan")

    def interval95(self) -> tuple[np.ndarray, np.ndarray]:
        """Linearised 95 % intervals: p +- 1.96 std, or for a log-transformed parameter
        exp(ln p +- 1.96 std / p) (the same linearisation made where the fit works)."""
        z = special.ndtri(0.975)
        lo, hi = self.p - z * self.std, self.p + z * self.std
        if self.log is not None and np.any(self.log):
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                f = np.exp(z * self.std / np.abs(self.p))
            lo = np.where(self.log, self.p / f, lo)
            hi = np.where(self.log, self.p * f, hi)
        return lo, hi


def chi2_sf(x: float, dof: int) -> float:
    """P(chi^2_dof > x) (scipy.special, to avoid importing scipy.stats at start-up)."""
    return float(special.gammaincc(dof / 2, x / 2)) if dof > 0 else float("nan")


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
    return Reliability(list(names), p, Cp, std, corr, s, Vt.T, cond, Q, np.diag(Q).copy(), rw.copy(), chi2, dof,
                       pval, float(m2logL), float(m2logL + 2 * n), float(m2logL + n * np.log(m)), undetermined,
                       np.asarray(params.log, bool))
