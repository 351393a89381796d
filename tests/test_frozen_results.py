"""Frozen results all the way down: an Identification, its Fit, its Reliability (with its linear
analysis and error scales) are values computed complete before construction; nothing can assign
into them or write into their arrays afterwards (derived values are new results, dataclasses.replace)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from conftest import CASES
from geoback.case.loading import load_case
from geoback.inference.identification import identify, prepare

pytestmark = pytest.mark.quick


@pytest.mark.parametrize("case", ["tunnel-paper.yaml", "tunnel-paper-error-scales.yaml"])
def test_identification_is_frozen_all_the_way_down(case):
    res = identify(prepare(load_case(CASES / case)), profile="none")
    fit, rel = res.fit, res.reliability
    objects = [(res, "seconds"), (fit, "p"), (fit, "status"), (fit, "history"), (fit.history[0], "p"),
               (rel, "covariance"), (rel, "error_scales"), (rel, "total_dof"), (rel.linear, "scale"),
               (rel.error_scales[0], "text")]
    for obj, name in objects:
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(obj, name, getattr(obj, name))
    arrays = [fit.p, fit.x, fit.A, fit.at_bound, fit.history[-1].p, rel.p, rel.covariance, rel.std, rel.correlation,
              rel.singular_values, rel.directions, rel.information_density, rel.leverage, rel.whitened_residual,
              rel.stated_residual, rel.information, rel.linear.covariance, rel.linear.std, rel.linear.rows]
    for a in arrays:
        assert isinstance(a, np.ndarray) and not a.flags.writeable
        with pytest.raises(ValueError):
            a.flat[0] = 0.0
    assert isinstance(fit.history, tuple) and isinstance(rel.error_scales, tuple) and isinstance(rel.names, tuple)
    assert fit.at_bound.dtype == bool
    assert "assess" in res.seconds and "fit" in res.seconds  # timed before the result was built
    # read-only values are fine inputs: a refit from the estimate, derived results by replace
    from geoback.inference.estimate import fit as refit

    analysis = prepare(load_case(CASES / case))
    again = refit(analysis.misfit, analysis.settings, p0=fit.p)
    np.testing.assert_allclose(again.p, fit.p, rtol=1e-6)
    later = dataclasses.replace(res, seconds={**res.seconds, "report": 0.0})
    assert later.fit is fit and "report" not in res.seconds
