"""Reliability of the estimate (eqns 43-55, whitened as in ERRATA.md).

With C_x = L L^t and A' = L^-1 A: C_p = (A'^t A' + C_p0^-1)^-1 (eqn 55, solved by
``linear_analysis.LinearAnalysis``, kept in the result as ``Reliability.linear``), Q = A' C_p A'^t
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

from dataclasses import dataclass

import numpy as np

from geoback.inference import chi2
from geoback.inference.frozen import readonly
from geoback.inference.linear_analysis import LinearAnalysis
from geoback.inference import scale_estimates as se
from geoback.inference import scales as sc

Z95 = 1.959963984540054  # standard normal quantile at 0.975


@dataclass(frozen=True)
class Reliability:
    """What eqns 43-55 say about an estimate p (computed complete by ``assess``; read-only arrays).

    With the whitened sensitivity A' = L^-1 A and residual r' = L^-1 (x* - x) at p (C_x = L L^t,
    re-weighted by the estimated error scales where there are any), m readings, n parameters:

    - ``names``, ``p``: the parameters and the estimate.
    - ``linear``: the linear analysis at p (``linear_analysis.LinearAnalysis`` of the rows
      [A'; C_p0^-1/2] equilibrated by |p|), from which the next four come.
    - ``covariance``: C_p = (A'^t A' + C_p0^-1)^-1, eqn 55 (over the determined directions).
    - ``std``: sqrt(diag C_p); inf for a parameter in an undetermined combination.
    - ``correlation``: C_p,ij / (std_i std_j) (nan where a std is infinite; 1 on the diagonal).
    - ``undetermined``: in words, the combinations (of relative changes dp/p) the readings and
      priors do not fix: singular values below ILL_CONDITIONED times the largest.
    - ``singular_values``, ``directions``: the SVD A' diag(|p|) = U S V^t of the readings alone
      (eqns 44-49, sensitivity to relative changes): S and the columns of V.
    - ``condition``: s_1 / s_n of that SVD (inf when s_n = 0).
    - ``information_density``: Q = A'_r C_z A'_r^t (m x m; A'_r = A' diag(|p|), C_z = C_p / (|p| |p|^t)),
      symmetric, idempotent without priors, trace n (ERRATA, Q); ``leverage`` its diagonal.
    - ``whitened_residual``: r' at p.
    - ``chi2``, ``dof``, ``p_value``: chi^2 = J_min (readings and priors) on m - n + (priors)
      degrees of freedom and P(chi^2_dof > chi2); with estimated scales, the readings whose sigma
      is known and the priors, on Satterthwaite's dof (module docstring).
    - ``minus2logL``: -2 ln L = J (or the support function S*, maximised over the scales) +
      ln |C_x| + m ln 2 pi (eqn 5); ``aic`` = -2 ln L + 2k, ``bic`` = -2 ln L + k ln m, k = n plus
      the estimated scales.
    - ``error_scales``: ``scale_estimates.ScaleEstimate`` per group of readings (eqn 10).
    - ``parameter_dof``: Satterthwaite dof of each std (None: every scale known).
    - ``ellipse_dof``: denominator dof of the parameters' F ellipse (inf: every scale known).
    - ``total_dof``: readings + priors - parameters.
    - ``stated_residual``: L^-1 (x* - x) with the stated C_x; ``stated_J``: J with every scale at 1.
    - ``log``: parameters identified as ln p (their intervals are made in log space).
    - ``information``: A'^t A' of the readings alone (no prior rows), physical units.
    """

    names: tuple[str, ...]
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
    dof: float
    p_value: float
    minus2logL: float
    aic: float
    bic: float
    undetermined: tuple[str, ...]  # plain-words description of combinations the readings cannot fix
    error_scales: tuple = ()  # scale_estimates.ScaleEstimate per group of readings
    parameter_dof: np.ndarray | None = None  # Satterthwaite dof of each std (None: every scale known)
    ellipse_dof: float = float("inf")  # denominator dof of the parameters' F ellipse
    total_dof: float = 0  # readings + priors - parameters
    stated_residual: np.ndarray | None = None  # L^-1 (x* - x) with the stated C_x
    stated_J: float = float("nan")  # J with every scale at 1 (data and priors)
    log: np.ndarray | None = None  # parameters identified as ln p: their intervals are made in log space
    information: np.ndarray | None = None  # A'^t A' of the readings alone (no prior rows), physical units
    linear: LinearAnalysis | None = None  # the posterior at p (eqn 55): covariance, predictions, data worth

    def __post_init__(self):
        set_ = object.__setattr__
        set_(self, "names", tuple(self.names))
        set_(self, "undetermined", tuple(self.undetermined))
        set_(self, "error_scales", tuple(self.error_scales))
        for name in ("p", "covariance", "std", "correlation", "singular_values", "directions",
                     "information_density", "leverage", "whitened_residual", "parameter_dof", "stated_residual",
                     "log", "information"):
            set_(self, name, readonly(getattr(self, name)))

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
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # (also where a parameter not
                f = np.exp(z * self.std / np.abs(self.p))  # on a log scale is 0: 0 * inf there, not used)
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


def relative_scale(p: np.ndarray) -> np.ndarray:
    """|p| (1 where p = 0): the reliability measures are made on relative parameter changes dp/p."""
    return np.where(np.abs(p) > 0, np.abs(p), 1.0)


def posterior(ev, params) -> LinearAnalysis:
    """The linear analysis at the misfit's Evaluation `ev` (eqn 55): the whitened readings' rows A'
    and the prior rows C_p0^-1/2, equilibrated by |p| (relative changes)."""
    return LinearAnalysis.from_rows(ev.whitened_sensitivity, params.prior_precision(), relative_scale(ev.p))


def assess(ev, params, logdet: float) -> Reliability:
    """Everything eqns 43-55 say about the optimum: `ev` is the misfit's Evaluation there (whitened
    residual r' and sensitivity A', prior rows), `logdet` = ln det of the weighting covariance."""
    names, p = params.names, ev.p
    Aw, rw = ev.whitened_sensitivity, ev.whitened_residual
    m, n = Aw.shape
    prec = params.prior_precision()
    la = posterior(ev, params)
    scale = la.scale
    As = Aw * scale  # sensitivity to relative changes dp/p
    U, s, Vt = np.linalg.svd(As, full_matrices=False)
    cond = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    undetermined = [combination_text(names, v) for v in la.undetermined_directions]
    Cp, std = la.covariance, la.std
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = Cp / np.outer(std, std)
    corr[~np.isfinite(corr)] = np.nan
    np.fill_diagonal(corr, 1.0)
    Q = As @ la.scaled_covariance @ As.T
    leverage = np.diag(Q).copy()
    groups = tuple(getattr(ev, "groups", ()) or ())
    state = getattr(ev, "scales", None)
    common = dict(names=names, p=p, covariance=Cp, std=std, correlation=corr, singular_values=s, directions=Vt.T,
                  condition=cond, information_density=Q, leverage=leverage, whitened_residual=rw,
                  undetermined=undetermined, log=np.asarray(params.log, bool), information=Aw.T @ Aw, linear=la)
    if state is None:
        chi2 = ev.J  # data and priors: the priors are observations too (dof counts them)
        dof = m - n + int(np.count_nonzero(prec))
        m2logL = float(chi2 + logdet + m * np.log(2 * np.pi))
        scales = []
        if groups:  # what each instrument's readings say about its stated sigma
            known = sc.profile_state(groups, rw, np.zeros(len(groups)))
            scales = se.group_estimates(known, sc_leverage(groups, leverage))
        return Reliability(**common, chi2=chi2, dof=dof, p_value=chi2_sf(chi2, dof), minus2logL=m2logL,
                           aic=float(m2logL + 2 * n), bic=float(m2logL + n * np.log(m)), error_scales=scales,
                           total_dof=dof, stated_residual=rw, stated_J=chi2)
    return Reliability(**common, **_with_scales(ev, params, logdet, groups, state, la, leverage,
                                                m - n + int(np.count_nonzero(prec))))


def sc_leverage(groups, leverage: np.ndarray) -> np.ndarray:
    return np.array([float(leverage[g.rows].sum()) for g in groups])


def _with_scales(ev, params, logdet, groups, state, la: LinearAnalysis, leverage, total_dof) -> dict:
    """The reliability measures that differ when error scales are estimated (module docstring)."""
    m, n = ev.m, len(ev.p)
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
        aug = la.rows
        full = aug @ la.scaled_covariance @ aug.T  # Q over readings and prior rows (relative scaling cancels)
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
    pdof = se.satterthwaite_dof(la.covariance, infos, nus) if not la.undetermined.any() else np.full(n, np.inf)
    edof = se.ellipse_dof(h, nus, n)
    stated = ev.stated_residual
    k = n + n_scales
    return dict(chi2=chi2, dof=dof, p_value=pval, minus2logL=float(m2logL), aic=float(m2logL + 2 * k),
                bic=float(m2logL + k * np.log(m)), error_scales=estimates, parameter_dof=pdof, ellipse_dof=edof,
                total_dof=total_dof, stated_residual=stated, stated_J=float(stated @ stated + prior_r @ prior_r))
