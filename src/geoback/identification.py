"""`geoback run`: mesh, fit, assess and write every output of one case."""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from .case import LoadedCase
from .estimate import Fit, Objective, fit
from .problem import Problem
from .reliability import Reliability, assess


@dataclass
class RunResult:
    problem: Problem
    fit: Fit
    reliability: Reliability
    objective: Objective
    seconds: dict


def reliability_of(problem: Problem, result: Fit, objective: Objective) -> Reliability:
    params = problem.params
    residual = objective.measured - result.x
    rp, _ = objective.prior_rows(result.p)
    return assess(params.names, result.p, result.A, residual, objective.L, params.prior_precision(),
                  J_prior=float(rp @ rp))


def identify(loaded: LoadedCase, method: str | None = None, problem: Problem | None = None,
             progress=None, weighting: str | None = None) -> RunResult:
    """Identify the case's parameters and assess the estimate (no files written)."""
    t0 = time.perf_counter()
    problem = problem or Problem(loaded)
    t1 = time.perf_counter()
    if problem.params.n == 0:
        from .errors import GeobackError

        raise GeobackError("the case lists no parameters to identify (add a 'parameters' section)")
    objective = Objective(problem, weighting or loaded.case.fit.weighting)
    result = fit(problem, method=method, progress=progress, weighting=weighting)
    t2 = time.perf_counter()
    rel = reliability_of(problem, result, objective)
    result.counts = {"factorisations": problem.counters.factorisations, "solves": problem.counters.solves,
                     "forward_runs": problem.counters.forward_runs}  # of the fit, before any output
    seconds = dict(problem.timings, setup=t1 - t0, fit=t2 - t1, assess=time.perf_counter() - t2)
    return RunResult(problem, result, rel, objective, seconds)


def run_case(loaded: LoadedCase, out: Path, method: str | None = None, progress=None,
             vtu: bool | None = None, plots: bool = False) -> RunResult:
    """identify() and write all outputs to `out` (atomically, file by file)."""
    from .report import write_run

    t0 = time.perf_counter()
    res = identify(loaded, method=method, progress=progress)
    res.seconds["total_before_output"] = time.perf_counter() - t0
    write_run(res, Path(out), vtu=loaded.case.output.vtu if vtu is None else vtu, plots=plots)
    return res

