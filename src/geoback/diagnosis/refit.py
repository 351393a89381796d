"""How a hypothesis is refitted and judged: the fit from the extended model, what a likelihood ratio
compares (J, or the support maximised over free error scales), the test and information criteria of a
refit, whether the readings determine its extra parameters,."""
from __future__ import annotations

import numpy as np

from geoback.case.limits import natural_limit
from geoback.inference.estimate import Fit, Settings, fit
from geoback.inference.identification import conclude
from geoback.inference.misfit import Misfit
from geoback.inference.reliability import chi2_sf
from geoback.diagnosis.results import Scored


REFIT_ITERATIONS = 100
WORSE = 1e-6  # relative: a refit whose objective exceeds its base's by more than this is worse than its base


def fit_and_assess(misfit: Misfit, settings: Settings, method: str, max_iterations=None, starts=None):
    """Fit `misfit` and assess it. `starts`: candidate starting points (the base model's optimum with
    the extension at its null value first, then e.g. a neighbouring refit's optimum); the fit starts
    from the one of lowest objective, so that (every accepted step lowering it) the refit ends no
    higher than the model it extends evaluated at the null start."""
    p0 = None
    if starts:
        best = None
        for q in starts:
            try:
                J = misfit.evaluate(np.asarray(q, float)).J
            except Exception:  # noqa: BLE001 - a start the model cannot solve is not taken
                continue
            if np.isfinite(J) and (best is None or J < best[0]):
                best = (J, np.asarray(q, float))
        p0 = None if best is None else best[1]
    res = fit(misfit, settings, method=method, max_iterations=max_iterations, p0=p0)
    return res, conclude(misfit, res, None, "", {}, {}).reliability


def null_start(misfit: Misfit) -> np.ndarray:
    """The extended misfit's start: the base optimum with every extension at its null value (its
    parameters' initial values, as ``Misfit.extended(start=p_hat)`` sets them)."""
    return np.array(misfit.parameters.initial, float)


def lr_objective(misfit: Misfit, f: Fit) -> float:
    """What a likelihood ratio compares: J, or with estimated scales the support function maximised
    over them (maximum-likelihood profile; restricted likelihoods of different models don't compare)."""
    if not misfit.free:
        return f.J
    return misfit.evaluate(f.p).support


def judge(s: Scored) -> None:
    """Whether the readings determine the refit's extra parameters: no 'not-determined' or
    'at-bound' caveat (geoback.inference.caveats) on any of them."""
    from geoback.inference.caveats import fit_caveats
    from geoback.inference.parameters import parameter_limits

    misfit, f = s.misfit, s.refit
    values = misfit.values(f.p)
    limits = [parameter_limits(misfit.simulation, n, values) for n in misfit.parameters.names]
    mine = set(s.hypothesis.names)
    found = fit_caveats(f, s.reliability, misfit.parameters, limits, {})
    s.caveats = [c for c in found if c.code in ("not-determined", "at-bound")
                 and (c.parameter in mine or (c.parameter is None and any(n in c.message for n in mine)))]
    s.determined = not s.caveats
    s.at_bound = at_bound(misfit, f, mine, limits)


def at_bound(misfit: Misfit, f: Fit, names, limits) -> dict:
    """{name: 'lower' | 'upper'} of the parameters among `names` the fit left on a search bound:
    the readings push them further, and an interval about them would say nothing. A bound at the
    parameter's natural limit (``limits[i]``: no preload) is not one: the readings found it there."""
    params = misfit.parameters
    out = {}
    for i, name in enumerate(params.names):
        if natural_limit(limits[i], f.p[i]):
            continue
        if name in names and bool(f.at_bound[i]):
            out[name] = "lower" if abs(f.p[i] - params.lower[i]) <= abs(f.p[i] - params.upper[i]) else "upper"
    return out


def compare(s: Scored, J0: float, searched: int, J_null: float | None = None) -> None:
    """Likelihood-ratio test and information criteria of a refitted hypothesis; `searched` counts
    extra quantities chosen by search rather than by the fit (a boundary's depth). `J_null`: the
    extended model's own objective at its null start where it is not the base model's J0 (another
    mesh: a split layer); the test takes the lower of the two, so that a mesh's own gain is never
    read as an effect. A refit ending above its base (dJ < 0 beyond round-off) is marked `worse`:
    it is no improvement, whatever its optimiser's status (``Scored.settled`` is False)."""
    extra = len(s.hypothesis.parameters) + searched
    if J_null is not None and np.isfinite(J_null):
        J0 = min(J0, J_null)
    s.J0 = J0
    s.dJ = J0 - lr_objective(s.misfit, s.refit)
    s.worse = bool(s.dJ < -WORSE * max(abs(J0), 1.0))
    s.p_lr = chi2_sf(max(s.dJ, 0.0), extra)
    m = len(s.reliability.whitened_residual)
    s.aic = s.reliability.aic + 2 * searched
    s.bic = s.reliability.bic + searched * np.log(m)
