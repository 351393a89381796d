"""Maximum-likelihood estimation by Gauss-Newton and Levenberg-Marquardt (eqns 6, 27-30).

The whitened problem is minimised: J(p) = ||L^-1 (x* - x(p))||^2 + sum prior terms, with
C_x = L L^t. Steps are taken in internal coordinates q (ln p for log-transformed parameters)
scaled by their initial magnitude, so that the paper's mu0 = 10 means the same whatever the
units: 'lm' adds mu * mean(diag N) * I to N = B^t B (eqn 30), 'lm-scaled' adds mu * diag(N)
(Marquardt), 'gn' uses mu = 0 (eqn 28) with step halving. mu is multiplied by 10 when J
rises and divided by 10 when it falls; a step is accepted only if J decreases.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .problem import Problem


MAX_TRIALS = 12  # trial steps per iteration (mu x10 or step halving each time)


@dataclass
class Iteration:
    k: int
    mu: float
    J: float
    p: np.ndarray
    accepted: bool


@dataclass
class Fit:
    p: np.ndarray
    J: float
    x: np.ndarray
    A: np.ndarray  # dx/dp at p (physical units)
    history: list[Iteration]
    status: str  # "converged" | "not converged"
    reason: str
    method: str
    iterations: int
    at_bound: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    counts: dict = field(default_factory=dict)  # factorisations, solves, forward runs (set by identify)


class Objective:
    """Whitened residuals of the data and of the priors, and their Jacobian in q."""

    def __init__(self, problem: Problem, weighting: str = "full"):
        self.problem = problem
        obs = problem.obs
        if obs.measured is None:
            from .errors import GeobackError

            raise GeobackError("the case has instruments without readings: give 'readings' or 'readings_file' "
                               "for every instrument to identify parameters")
        self.measured = obs.measured
        self.weighting = weighting
        C = obs.covariance
        if weighting == "identity":
            C = np.eye(obs.m)
        elif weighting == "diagonal":
            C = np.diag(np.diag(C))
        self.C = C
        self.L = np.linalg.cholesky(C) if weighting == "full" else np.diag(np.sqrt(np.diag(C)))
        self.params = problem.params
        span = np.where(np.isfinite(self.params.upper - self.params.lower), (self.params.upper - self.params.lower) / 10, 1.0)
        typical = np.where(self.params.initial != 0, np.abs(self.params.initial), span)
        self.scale = np.where(self.params.log, 1.0, typical)  # q / scale is O(1) for every parameter

    def whiten(self, v: np.ndarray) -> np.ndarray:
        from scipy.linalg import solve_triangular

        return solve_triangular(self.L, v, lower=True)

    def prior_rows(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        has = self.params.has_prior
        sq = np.sqrt(self.params.prior_precision())[has]
        r = sq * (self.params.prior_mean[has] - p[has])
        Jp = np.zeros((int(has.sum()), len(p)))
        Jp[np.arange(int(has.sum())), np.flatnonzero(has)] = sq
        return r, Jp

    def evaluate(self, z: np.ndarray, with_jacobian: bool):
        """Residual vector r_aug (whitened data, then priors) and B = d x_aug / d z at z = q / scale."""
        q = z * self.scale
        p = self.params.to_physical(q)
        if with_jacobian:
            x, A = self.problem.predict_with_sensitivity(p)
        else:
            x, A = self.problem.predict(p), None
        rp, Jp = self.prior_rows(p)
        r = np.concatenate([self.whiten(self.measured - x), rp])
        B = None
        if with_jacobian:
            chain = self.params.dp_dq(q) * self.scale
            B = np.vstack([self.whiten(A), Jp]) * chain
        return p, x, A, r, B

    def J(self, r: np.ndarray) -> float:
        return float(r @ r)


def _solve_step(N: np.ndarray, g: np.ndarray, damping: np.ndarray) -> np.ndarray:
    M = N + np.diag(damping)
    try:
        c = np.linalg.cholesky(M)
        return np.linalg.solve(c.T, np.linalg.solve(c, g))
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(M, g, rcond=None)[0]


def fit(problem: Problem, method: str | None = None, p0: np.ndarray | None = None,
        max_iterations: int | None = None, weighting: str | None = None, progress=None) -> Fit:
    """Identify the case's parameters (eqns 27-30); never raises on non-convergence."""
    settings = problem.case.fit
    method = method or settings.method
    max_iterations = max_iterations or settings.max_iterations
    obj = Objective(problem, weighting or settings.weighting)
    params = problem.params
    lo_q, hi_q = params.internal_bounds()
    lo, hi = lo_q / obj.scale, hi_q / obj.scale
    z = params.to_internal(params.initial if p0 is None else p0) / obj.scale
    p, x, A, r, B = obj.evaluate(z, True)
    J = obj.J(r)
    mu = 0.0 if method == "gn" else settings.mu0
    history = [Iteration(0, mu, J, p.copy(), True)]
    status, reason = "not converged", f"maximum number of iterations ({max_iterations}) reached"
    k = 0

    def damping(N):
        if method == "lm":
            return np.full(len(z), mu * np.mean(np.diag(N)))
        if method == "lm-scaled":
            return mu * np.diag(N)
        return np.zeros(len(z))

    while k < max_iterations:
        k += 1
        N, g = B.T @ B, B.T @ r
        step = _solve_step(N, g, damping(N))
        predicted = 2 * g @ step - step @ N @ step  # decrease of J predicted by the linear model
        if predicted <= settings.objective_tol * J:
            k -= 1
            status, reason = "converged", f"predicted decrease of J ({predicted:.1e}) below tolerance"
            break
        accepted = False
        for _trial in range(MAX_TRIALS):
            z_new = np.clip(z + step, lo, hi)
            p_new, _, _, r_new, _ = obj.evaluate(z_new, False)
            J_new = obj.J(r_new)
            accepted = J_new < J
            history.append(Iteration(k, mu, J_new, p_new.copy(), accepted))
            if progress:
                progress(history[-1])
            if accepted:
                break
            if method == "gn":
                step = step / 2
            else:
                mu *= 10
                step = _solve_step(N, g, damping(N))
        if not accepted:
            status, reason = "converged", "no step decreases J any more (minimum to working precision)"
            break
        dz = z_new - z
        dJ = (J - J_new) / max(J, 1e-300)
        z, J = z_new, J_new
        if method != "gn":
            mu /= 10
        p, x, A, r, B = obj.evaluate(z, True)
        rel_step = np.max(np.abs(dz) / np.maximum(np.abs(z), 1e-12))
        if rel_step < settings.step_tol:
            status, reason = "converged", f"relative step {rel_step:.1e} below {settings.step_tol:g}"
            break
        if dJ < settings.objective_tol:
            status, reason = "converged", f"relative change of J {dJ:.1e} below {settings.objective_tol:g}"
            break
    at_bound = (np.isclose(z, lo) & np.isfinite(lo)) | (np.isclose(z, hi) & np.isfinite(hi))
    if status == "converged" and at_bound.any():
        reason += "; at a bound: " + ", ".join(n for n, b in zip(params.names, at_bound) if b)
    return Fit(p, J, x, A, history, status, reason, method, k, at_bound)
