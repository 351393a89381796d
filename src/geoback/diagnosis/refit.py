"""How a hypothesis is refitted and judged: the fit from the extended model, what a likelihood ratio
compares (J, or the support maximised over free error scales), the test and information criteria of a
refit, whether the readings determine its extra parameters,."""
from __future__ import annotations

import numpy as np

from geoback.inference.estimate import Fit, Settings, fit
from geoback.inference.identification import conclude
from geoback.inference.misfit import Misfit
from geoback.inference.reliability import chi2_sf
from geoback.diagnosis.results import Scored


REFIT_ITERATIONS = 100


def fit_and_assess(misfit: Misfit, settings: Settings, method: str, max_iterations=None):
    res = fit(misfit, settings, method=method, max_iterations=max_iterations)
    return res, conclude(misfit, res, None, "", {}, {}).reliability


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


def compare(s: Scored, J0: float, searched: int) -> None:
    """Likelihood-ratio test and information criteria of a refitted hypothesis; `searched` counts
    extra quantities chosen by search rather than by the fit (a boundary's depth)."""
    extra = len(s.hypothesis.parameters) + searched
    s.J0 = J0
    s.dJ = J0 - lr_objective(s.misfit, s.refit)
    s.p_lr = chi2_sf(max(s.dJ, 0.0), extra)
    m = len(s.reliability.whitened_residual)
    s.aic = s.reliability.aic + 2 * searched
    s.bic = s.reliability.bic + searched * np.log(m)
