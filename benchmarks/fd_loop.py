"""What the benchmarks compare geoback against: scipy.optimize.least_squares with 2-point finite
differences on the same whitened residuals, in variables scaled by the initial values, every call
a forward run from scratch (`simulation.release()`: an external code remembers nothing between
runs, so each run assembles and factorises)."""
from __future__ import annotations

import time

import numpy as np


def fd_least_squares(misfit, parameters, method: str = "trf", tolerate_failures: bool = False) -> dict:
    """Fit `parameters` (a ParameterSet) of `misfit` by least_squares (2-point Jacobian); 'lm' has no
    bounds. tolerate_failures: a forward run that raises returns a large residual, as wrappers do.
    Returns the result `ls`, the estimate `p`, `calls`, `failed` and the fit's wall `seconds`."""
    from scipy.optimize import least_squares

    sim = misfit.simulation
    p0 = parameters.initial.copy()
    scale = np.abs(p0)
    calls = {"n": 0, "failed": 0}

    def fun(z):
        calls["n"] += 1
        sim.release()
        if not tolerate_failures:
            return misfit.evaluate(z * scale).r
        try:
            return misfit.evaluate(z * scale).r
        except Exception:  # noqa: BLE001 - a failed forward run
            calls["failed"] += 1
            return np.full(misfit.m, 1e6)

    bounds = {} if method == "lm" else {"bounds": (parameters.lower / scale, parameters.upper / scale)}
    t0 = time.perf_counter()
    ls = least_squares(fun, p0 / scale, jac="2-point", method=method, **bounds)
    return dict(ls=ls, p=ls.x * scale, jacobian=ls.jac / scale, calls=calls["n"], failed=calls["failed"],
                seconds=time.perf_counter() - t0)
