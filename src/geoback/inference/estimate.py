"""Maximum-likelihood estimation by Gauss-Newton and Levenberg-Marquardt (eqns 6, 27-30).

Minimises J(p) = r(p)^t r(p) of a ``Misfit`` (whitened residuals and prior rows). Steps are
taken in internal coordinates z = q / scale, with q = ln p for log-transformed parameters and
scale the initial magnitude, so that the paper's mu0 = 10 means the same whatever the units:
'lm' adds mu * mean(diag N) * I to N = B^t B (eqn 30), 'lm-scaled' adds mu * diag(N) (Marquardt),
'gn' uses mu = 0 (eqn 28) with step halving. mu is multiplied by 10 when J rises and divided by
10 when it falls; a step is accepted only if J decreases and the sensitivities there are computed
too. A trial point where the model cannot be solved (``errors.ForwardFailure``: a non-linear
forward run that did not converge), for its readings or for their sensitivities, counts as a rise
of J (recorded as J = inf in the history; the latter also as a 'model-unsolved' warning): the fit
goes on from its best point, never lost; at the initial values it is an error. Past the time limit
of ``case.budget`` the fit stops with its best accepted point (status 'not converged', a
'time-limit' warning; ``Fit.warnings``). When the
simulation's readings are only piecewise smooth in the parameters (``Simulation.piecewise_smooth``:
elastoplastic ground, whose J has a kink wherever a quadrature point starts to yield in another load
increment), the gradient does not vanish at the minimum; the fit then also stops after two accepted
steps in a row that lowered J by less than PIECEWISE_TOL (0.01 in chi-square units: the estimate
then moves by about a tenth of its standard deviation at most). The internal coordinates never leave
this module: the misfit is evaluated in physical units.

The optimiser knows nothing of error scales: a misfit that estimates them reports its profiled
objective as J (which may be negative, hence the relative tests on |J|) with re-weighted r and B
whose -2 B^t r is its gradient. A misfit whose objective depends on where its optimum is (the
scales' restricted degrees of freedom, ``Misfit.anchored``) is refitted from the optimum until
that stops changing; for every other misfit ``anchored`` returns the misfit itself and the fit is
a single run of the loop.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from geoback.case import budget
from geoback.errors import ForwardFailure, TimeLimit
from geoback.inference.frozen import readonly
from geoback.inference.misfit import Misfit
from geoback.inference.parameters import ParameterSet

MAX_TRIALS = 12  # trial steps per iteration (mu x10 or step halving each time)
WARNINGS = {  # codes of Fit.warnings (caveat codes of the result)
    "time-limit": "the fit was stopped at the time limit (geoback.case.budget, --time-limit) with its best point",
    "model-unsolved": "a point that lowered J had no solution with its sensitivities: rejected, the fit kept the "
                      "best point where the model could be solved",
}
PIECEWISE_TOL = 1e-2  # J units: smaller falls of J are not meaningful when the readings have kinks
MAX_SETTLE = 8  # refits from the optimum while the misfit's anchored settings change
METHODS = ("lm", "gn", "lm-scaled")


@dataclass(frozen=True)
class Settings:
    """Fit settings (the case's ``fit:`` section)."""

    method: str = "lm"
    max_iterations: int = 30
    mu0: float = 10.0
    step_tol: float = 1e-6
    objective_tol: float = 1e-10

    @classmethod
    def of(cls, fit_section) -> "Settings":
        return cls(fit_section.method, fit_section.max_iterations, fit_section.mu0, fit_section.step_tol,
                   fit_section.objective_tol)


@dataclass(frozen=True)
class Iteration:
    """One trial point of the fit: iteration k, the damping mu it was tried with (eqn 30), J there
    (inf where the model could not be solved) and whether the step was accepted (J decreased)."""

    k: int
    mu: float
    J: float
    p: np.ndarray
    accepted: bool

    def __post_init__(self):
        object.__setattr__(self, "p", readonly(self.p))


@dataclass(frozen=True)
class Fit:
    """What the optimiser found (eqns 27-30): a frozen value, built complete by ``fit``; read-only arrays.

    - ``p``: the estimate, the last accepted point (physical units).
    - ``J``: J(p) = r^t r, the whitened sum of squares with the prior rows (eqns 6, 9; the profiled
      objective S* when error scales are estimated).
    - ``x``: the computed readings x(p); ``A``: their sensitivity dx/dp at p (eqns 34-42, physical units).
    - ``history``: every trial point (``Iteration``: iteration k, damping mu, J, p, accepted), in order.
    - ``status``: 'converged' or 'not converged'; ``reason``: why the loop stopped, in words.
    - ``method``: 'lm' (eqn 30), 'lm-scaled' (Marquardt) or 'gn' (eqn 28).
    - ``iterations``: iterations made (over all refits from the optimum while the misfit settled).
    - ``at_bound``: which parameters ended on a bound.
    - ``moved``: False when stuck at the initial values (no step decreased J, yet J was not at a minimum).
    - ``warnings``: (code, message) pairs (``WARNINGS``): the fit was stopped at the time limit, or a point
      that lowered J could not be solved for its sensitivities and the fit kept the best point that could.
    """

    p: np.ndarray
    J: float
    x: np.ndarray
    A: np.ndarray  # dx/dp at p (physical units)
    history: tuple[Iteration, ...]
    status: str  # "converged" | "not converged"
    reason: str
    method: str
    iterations: int
    at_bound: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    moved: bool = True  # False: stuck at the initial values (no step decreased J, yet J was not at a minimum)
    warnings: tuple = ()  # (code, message): what the result should be read with (WARNINGS)

    def __post_init__(self):
        object.__setattr__(self, "history", tuple(self.history))
        object.__setattr__(self, "warnings", tuple(self.warnings))
        for name in ("p", "x", "A", "at_bound"):
            object.__setattr__(self, name, readonly(getattr(self, name)))


class _Coordinates:
    """z = q / scale with q = ln p (log-transformed) or p."""

    def __init__(self, params: ParameterSet):
        self.log = params.log
        span = np.where(np.isfinite(params.upper - params.lower), (params.upper - params.lower) / 10, 1.0)
        typical = np.where(params.initial != 0, np.abs(params.initial), span)
        self.scale = np.where(params.log, 1.0, typical)
        lo = np.where(params.log, np.log(np.where(params.lower > 0, params.lower, 1.0)), params.lower)
        hi = np.where(params.log, np.log(np.where(params.upper > 0, params.upper, 1.0)), params.upper)
        lo = np.where(params.log & ~(params.lower > 0), -np.inf, lo)
        self.lo, self.hi = lo / self.scale, hi / self.scale

    def z(self, p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, float)
        return np.where(self.log, np.log(np.where(self.log, p, 1.0)), p) / self.scale

    def p(self, z: np.ndarray) -> np.ndarray:
        q = np.asarray(z, float) * self.scale
        return np.where(self.log, np.exp(np.where(self.log, q, 0.0)), q)

    def dp_dz(self, z: np.ndarray) -> np.ndarray:
        return np.where(self.log, self.p(z), 1.0) * self.scale


def _solve_step(N: np.ndarray, g: np.ndarray, damping: np.ndarray) -> np.ndarray:
    M = N + np.diag(damping)
    try:
        c = np.linalg.cholesky(M)
        return np.linalg.solve(c.T, np.linalg.solve(c, g))
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(M, g, rcond=None)[0]


def fit(misfit: Misfit, settings: Settings = Settings(), method: str | None = None, p0: np.ndarray | None = None,
        max_iterations: int | None = None, progress=None) -> Fit:
    """Identify the misfit's parameters (eqns 27-30); never raises on non-convergence."""
    result = _iterate(misfit, settings, method, p0, max_iterations, progress)
    for _ in range(MAX_SETTLE):
        settled = misfit.anchored(result.p)
        if settled is misfit:
            break
        misfit = settled  # near the optimum already: restart with the damping the last round ended with
        mu = [h.mu for h in result.history if h.accepted][-1]
        warm = replace(settings, mu0=max(mu, 1e-12 * settings.mu0))
        shown = (lambda it, k0=result.iterations: progress(replace(it, k=it.k + k0))) if progress else None
        again = _iterate(misfit, warm, method, result.p, max_iterations, shown)
        result = replace(again, history=result.history + tuple(replace(h, k=h.k + result.iterations)
                                                               for h in again.history),
                         iterations=again.iterations + result.iterations, moved=again.moved or result.moved,
                         warnings=tuple({**dict(result.warnings), **dict(again.warnings)}.items()))
        if "time-limit" in dict(again.warnings):
            break
    return result


def _iterate(misfit: Misfit, settings: Settings, method: str | None, p0: np.ndarray | None,
             max_iterations: int | None, progress) -> Fit:
    method = method or settings.method
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, not '{method}'")
    max_iterations = max_iterations or settings.max_iterations
    params = misfit.parameters
    co = _Coordinates(params)
    lo, hi = co.lo, co.hi
    z = co.z(params.initial if p0 is None else p0)
    try:
        ev = misfit.evaluate(co.p(z), jacobian=True)
    except ForwardFailure as exc:
        start = ", ".join(f"{n} = {v:.6g}" for n, v in zip(params.names, co.p(z)))
        raise ForwardFailure(f"the model cannot be solved at the values the fit starts from ({start}): {exc}") from None
    J = ev.J
    B = ev.B * co.dp_dz(z)
    mu = 0.0 if method == "gn" else settings.mu0
    history = [Iteration(0, mu, J, ev.p, True)]
    status, reason = "not converged", f"maximum number of iterations ({max_iterations}) reached"
    k = 0
    moved = False

    def damping(N):
        if method == "lm":
            return np.full(len(z), mu * np.mean(np.diag(N)))
        if method == "lm-scaled":
            return mu * np.diag(N)
        return np.zeros(len(z))

    floor = PIECEWISE_TOL if getattr(misfit.simulation, "piecewise_smooth", False) else 0.0
    small = 0  # accepted steps in a row that lowered J by less than the floor
    warnings: dict = {}
    unsolved = []  # J at points that lowered it but had no solution with sensitivities

    def out_of_time(where: str) -> bool:
        if not budget.expired(where):
            return False
        warnings["time-limit"] = (f"the fit was stopped at {budget.describe_limit()} in iteration {k} with the best "
                                  f"point it had reached (J = {J:.6g}); it had not converged")
        return True

    while k < max_iterations:
        if out_of_time(f"iteration {k + 1} of the fit"):
            status, reason = "not converged", f"stopped at {budget.describe_limit()}: the estimate is the best point reached"
            break
        k += 1
        N, g = B.T @ B, B.T @ ev.r
        step = _solve_step(N, g, damping(N))
        predicted = 2 * g @ step - step @ N @ step  # decrease of J predicted by the linear model
        if predicted <= max(settings.objective_tol * abs(J), floor):
            k -= 1
            status, reason = "converged", f"predicted decrease of J ({predicted:.1e}) below tolerance"
            moved = True  # at the minimum already: nowhere to move
            break
        accepted, stopped = False, False
        for _trial in range(MAX_TRIALS):
            if _trial and out_of_time(f"trial {_trial + 1} of iteration {k} of the fit"):
                stopped = True
                break
            z_new = np.clip(z + step, lo, hi)
            p_new = co.p(z_new)
            ev_new = None
            try:
                J_new = misfit.J(p_new)
                if J_new < J:  # a point that lowers J: accepted once its sensitivities are known too
                    try:
                        ev_new = misfit.evaluate(p_new, jacobian=True)
                    except ForwardFailure:
                        unsolved.append(J_new)
                        J_new = np.inf
            except ForwardFailure:  # the model cannot be solved there (a non-linear run failed): a rejected step
                J_new = np.inf
            except TimeLimit:  # the time limit passed inside a forward run: stop with the best point
                out_of_time(f"trial {_trial + 1} of iteration {k} of the fit")
                stopped = True
                break
            accepted = J_new < J
            history.append(Iteration(k, mu, J_new, p_new, accepted))
            if progress:
                progress(history[-1])
            if accepted:
                break
            if method == "gn":
                step = step / 2
            else:
                mu *= 10
                step = _solve_step(N, g, damping(N))
        if stopped:
            status, reason = "not converged", f"stopped at {budget.describe_limit()}: the estimate is the best point reached"
            break
        if not accepted:
            if moved:
                status, reason = "converged", "no step decreases J any more (minimum to working precision)"
            else:
                status, reason = "not converged", "no step from the initial values decreases J: stopped without moving"
            break
        moved = True
        dz = z_new - z
        fall = J - J_new
        dJ = fall / max(abs(J), 1e-300)
        z, J = z_new, J_new
        if method != "gn":
            mu /= 10
        ev = ev_new
        B = ev.B * co.dp_dz(z)
        rel_step = np.max(np.abs(dz) / np.maximum(np.abs(z), 1e-12))
        if rel_step < settings.step_tol:
            status, reason = "converged", f"relative step {rel_step:.1e} below {settings.step_tol:g}"
            break
        if dJ < settings.objective_tol:
            status, reason = "converged", f"relative change of J {dJ:.1e} below {settings.objective_tol:g}"
            break
        small = small + 1 if fall < floor else 0
        if small == 2:
            status, reason = "converged", (f"J fell by less than {floor:g} twice: the readings are only piecewise "
                                           f"smooth in the parameters (ground switching between elastic and "
                                           f"plastic), a smaller change is no improvement of the fit")
            break
    at_bound = (np.isclose(z, lo) & np.isfinite(lo)) | (np.isclose(z, hi) & np.isfinite(hi))
    if status == "converged" and at_bound.any():
        reason += "; at a bound: " + ", ".join(n for n, b in zip(params.names, at_bound) if b)
    if unsolved:
        warnings["model-unsolved"] = (
            f"the model had no solution with its sensitivities at {len(unsolved)} point(s) that lowered J (to "
            f"{min(unsolved):.6g}): they were rejected steps, and the estimate is the best point where it could be "
            f"solved (J = {ev.J:.6g})")
    return Fit(ev.p, ev.J, ev.x, ev.A, history, status, reason, method, k, at_bound, moved, tuple(warnings.items()))
