"""Where the load increments of an elastoplastic run end, and exact shortcuts through elastic spans.

``Steps``: inside stage i an increment ends at lambda = lambda_(i-1) + s (lambda_i - lambda_(i-1)),
s in (0, 1]: a fixed schedule (``Options.schedule``; with ``refine`` a failed increment is halved,
the ends still to reach kept in ``pending``) or an adaptive one (the step grows after quick
convergence, halves after a failure).

``elastic_reach``: from a state whose tangent is the elastic stiffness K_e, the response is linear
as long as every point stays elastic, so several increments of a fixed schedule give the same
solution (and the same sensitivities) as one. The trial stress of an elastic step is linear in
lambda and the Mohr-Coulomb surface (with its cut-off) is convex, so if the trial at an end is
admissible everywhere so is every trial before it: the furthest such end of the stage is found by
bisection with one back-substitution (w = K_e^-1 f) and the ends before it are dropped; that
increment is then solved as the linear step it is, without Newton (``_Problem.elastic_step``: a
Newton test of the residual against a tiny release, beta = 1e-6, was below rounding and failed).
The schedule a run records (``Result.schedule``) lists the increments it used, so a replay is the same.
"""
from __future__ import annotations

import numpy as np

from geoback.physics.plasticity import mohr_coulomb as mc


class Steps:
    """Where increments end inside a stage (fractions s of it): a fixed schedule, or adaptive
    (the step, a lambda difference, is carried from stage to stage). A fixed schedule with
    ``refine`` halves a failed increment (the ends still to reach are kept in ``pending``)."""

    def __init__(self, opts, lam_end: float):  # opts: incremental.Options
        self.opts, self.lam_end = opts, lam_end
        self.step = opts.first_increment * lam_end

    def stage(self, i: int, lam_a: float, lam_b: float):
        self.lam_a, self.lam_b = lam_a, lam_b
        self.pending = None
        if self.opts.schedule is not None:
            fixed = [float(x) for x in np.atleast_1d(self.opts.schedule[i])]
            if not fixed or fixed[-1] != 1.0 or fixed[0] <= 0 or np.any(np.diff(fixed) <= 0):
                raise ValueError(f"schedule of stage {i + 1} must increase to exactly 1, found {fixed}")
            self.pending = fixed
        self.used = []

    def next(self, s: float) -> float:
        if self.pending is not None:
            return self.pending[0]
        s_new = min(1.0, s + self.step / (self.lam_b - self.lam_a))
        return 1.0 if 1.0 - s_new < 1e-9 else s_new

    def lam(self, s: float) -> float:
        return self.lam_b if s == 1.0 else self.lam_a + s * (self.lam_b - self.lam_a)

    def converged(self, s: float, iterations: int) -> None:
        self.used.append(s)
        if self.pending is not None:
            self.pending.pop(0)
        elif iterations <= self.opts.fast:
            self.step = min(self.step * self.opts.growth, self.opts.max_increment * self.lam_end)

    def failed(self, dlam: float) -> str | None:
        """Cut the step back; the reason to give up, if any."""
        if self.pending is not None and not self.opts.refine:
            return "fixed schedule"
        if 0.5 * dlam < self.opts.min_increment * self.lam_end:
            return f"increment cut below {self.opts.min_increment:g} of the final lambda"
        if self.pending is not None:
            s_prev = self.used[-1] if self.used else 0.0
            self.pending.insert(0, 0.5 * (s_prev + self.pending[0]))
        else:
            self.step = 0.5 * dlam
        return None


def elastic_reach(problem, state, steps: Steps, elastic) -> bool:
    """Drop the pending ends of this stage before the furthest one an elastic step from `state`
    reaches with every point elastic (`elastic`: the factorised K_e); see the module docstring.
    True when that end (the next one) is reached so: the increment is then one exact linear step."""
    pending = steps.pending
    if pending is None or not pending:
        return False
    _, w = problem.elastic_response(elastic)

    def admissible(k: int) -> bool:
        dlam = steps.lam(pending[k]) - state.lam
        trial = mc.trial_stress(state.sigma, dlam * w, problem.mat)
        return bool(np.all(mc.select(trial, problem.mat) == mc.ELASTIC))

    lo, hi = 0, len(pending) - 1  # find the last admissible index
    if not admissible(0):
        return False
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if admissible(mid):
            lo = mid
        else:
            hi = mid - 1
    del pending[:lo]
    return True
