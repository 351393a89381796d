"""Many identifications of one case on other readings (Monte Carlo studies, calibration of C_p):
one simulation and one misfit reused, so that the paper case's thousand fits share one
factorisation. Exposed as ``geoback.inference.identification.identify_replicates``."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geoback.inference.estimate import fit
from geoback.inference.reliability import assess, posterior


@dataclass(frozen=True)
class Replicates:
    """Estimates of many identifications of one case on other readings (Monte Carlo studies)."""

    p: np.ndarray  # (N, n)
    std: np.ndarray  # (N, n) linearised standard deviations at each estimate
    covariance: np.ndarray  # (N, n, n)
    J: np.ndarray  # (N,)
    converged: np.ndarray  # (N,) bool
    at_bound: np.ndarray  # (N, n) bool
    names: list[str]
    # estimated error scales (None when every scale is known): k per group and its interval,
    # and the denominator dof of each replicate's parameter ellipse (Reliability.ellipse_limit)
    scale_names: list[str] | None = None
    scales: np.ndarray | None = None  # (N, G)
    scale_low: np.ndarray | None = None
    scale_high: np.ndarray | None = None
    ellipse_dof: np.ndarray | None = None  # (N,)
    ellipse_limit: np.ndarray | None = None  # (N,) 95 % limit of d^2
    scale_dof: np.ndarray | None = None  # (N, G) restricted dof c_g = m_g - h_g of each estimated scale

    def inside(self, truth: np.ndarray, level: float = 0.95) -> np.ndarray:
        """Is `truth` inside each replicate's `level` ellipse (F ellipse when scales are estimated)?"""
        from scipy import special

        from geoback.inference.scale_estimates import chi2_ppf

        e = self.p - np.asarray(truth, float)
        d2 = np.einsum("ki,ki->k", e, np.linalg.solve(self.covariance, e[..., None])[..., 0])
        n = self.p.shape[1]
        if self.ellipse_dof is None:
            return d2 < chi2_ppf(level, n)
        finite = np.isfinite(self.ellipse_dof)
        limit = np.where(finite, n * special.fdtri(n, np.where(finite, self.ellipse_dof, 1.0), level),
                         chi2_ppf(level, n))
        return d2 < limit


def identify_replicates(analysis, measured: np.ndarray, method: str | None = None,
                        p0: np.ndarray | None = None) -> Replicates:
    """Identify the case's parameters from each row of `measured` (N x m readings), reusing one
    simulation (one factorisation when K = E k) and one misfit; for calibration studies."""
    from threadpoolctl import threadpool_limits

    measured = np.atleast_2d(np.asarray(measured, float))
    base = analysis.misfit
    n = base.n
    N = len(measured)
    P, S, C, J = np.empty((N, n)), np.empty((N, n)), np.empty((N, n, n)), np.empty(N)
    ok, bound = np.zeros(N, bool), np.zeros((N, n), bool)
    est = [k for k, g in enumerate(base.scales) if g.estimated]
    K, lo, hi, dof = (np.full((N, len(est)), np.nan) for _ in range(4))
    edof, elim = np.full(N, np.inf), np.full(N, np.nan)
    # thousands of tiny dense solves: BLAS threads only add start-up cost (and spin on a busy machine)
    with threadpool_limits(limits=1, user_api="blas"):
        for i, x in enumerate(measured):
            mis = base.with_measured(x)
            f = fit(mis, analysis.settings, method=method, p0=p0)
            if est:  # the scales estimated at this replicate's optimum, C_p with them, the F ellipse
                mis = mis.anchored(f.p)
                rel = assess(mis.evaluate(f.p, jacobian=True), mis.parameters, mis.logdet)
                la = rel.linear
                K[i] = [rel.error_scales[k].factor for k in est]
                lo[i] = [rel.error_scales[k].low for k in est]
                hi[i] = [rel.error_scales[k].high for k in est]
                dof[i] = [rel.error_scales[k].dof for k in est]
                edof[i], elim[i] = rel.ellipse_dof, rel.ellipse_limit(0.95)
            else:  # C_p = (A'^t A' + C_p0^-1)^-1, eqn 55, as `assess` makes it
                la = posterior(mis.evaluate(f.p, jacobian=True), mis.parameters)
            P[i], C[i], S[i], J[i] = f.p, la.covariance, la.std, f.J
            ok[i], bound[i] = f.status == "converged", f.at_bound
    if not est:
        return Replicates(P, S, C, J, ok, bound, list(base.parameters.names))
    return Replicates(P, S, C, J, ok, bound, list(base.parameters.names), [base.scales[k].name for k in est],
                      K, lo, hi, edof, elim, dof)
